"""One file rewritten with the newest content handed to it, written on its own thread.

The caller (the pipeline thread, after every frame) never waits for the disk, and content superseded before it
was written is skipped: readers only ever want the newest. The content is made on the writer thread too (a
function returning the bytes: serialising is part of the cost taken off the caller).
"""
from __future__ import annotations

import threading
from collections.abc import Callable


class LatestFile:
    """``put(make)`` hands over the newest content; ``close()`` writes what is pending, then stops the thread.
    ``write(data)`` writes it; an error it raises goes to ``on_error`` and the next content is still written."""

    def __init__(self, write: Callable[[bytes], None], on_error: Callable[[Exception], None],
                 name: str = "vtdslam-latest-file") -> None:
        self._write, self._on_error = write, on_error
        self._cond = threading.Condition()
        self._pending: Callable[[], bytes] | None = None
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def put(self, make: Callable[[], bytes]) -> None:
        with self._cond:
            self._pending = make
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                make, self._pending = self._pending, None
            if make is None:  # closed, nothing left to write
                return
            try:
                self._write(make())
            except Exception as exc:  # noqa: BLE001 - the owner decides what a failed write means
                self._on_error(exc)

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify()
        self._thread.join()
