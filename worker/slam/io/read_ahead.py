"""Decoding the next frames of a sequence on a background thread, so reading overlaps tracking.

JPEG/PNG decoding in OpenCV releases the GIL, so a reader thread a few frames ahead hides most of the read
cost behind the per-frame stages. The queue is bounded (`depth` frames), so memory stays at a few frames.
Frames come out in order and unchanged; an error reading frame i is raised when frame i is asked for, as a
synchronous read would.
"""
from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterator, Sequence
from types import TracebackType
from typing import Generic, TypeVar

_POLL_S = 0.05
"""How often a blocked reader checks whether it should stop (the consumer may have gone away)."""

T = TypeVar("T")
"""What `read(i)` gives: a `Frame`, or a frame with work queued on it (`prepare_ahead.Prepared`)."""


class ReadAhead(Generic[T]):
    """Iterates `read(i)` for i in `indices`, decoding up to `depth` frames ahead on one thread.

    `depth` 0 reads synchronously on the caller's thread (no thread at all). Use as a context manager, so an
    exception or cancellation in the consumer stops the reader thread.
    """

    def __init__(self, read: Callable[[int], T], indices: Sequence[int], depth: int = 2) -> None:
        if depth < 0:
            raise ValueError(f"read-ahead depth must be >= 0, got {depth}")
        self._read = read
        self._indices = indices
        self._depth = depth
        self._queue: queue.Queue[tuple[T | None, BaseException | None]] = queue.Queue(maxsize=max(1, depth))
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __enter__(self) -> ReadAhead[T]:
        if self._depth > 0 and len(self._indices):
            self._thread = threading.Thread(target=self._produce, name="vtdslam-read-ahead", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Stop the reader thread and wait for it (at most one frame's decoding)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def __iter__(self) -> Iterator[T]:
        if self._depth == 0:
            for i in self._indices:
                yield self._read(i)
            return
        if self._thread is None:
            raise RuntimeError("ReadAhead must be entered (with ReadAhead(...) as frames) before iterating")
        for _ in range(len(self._indices)):
            frame, error = self._queue.get()
            if error is not None:
                raise error
            assert frame is not None
            yield frame

    def _produce(self) -> None:
        for i in self._indices:
            try:
                item: tuple[T | None, BaseException | None] = (self._read(i), None)
            except BaseException as exc:  # handed to the consumer at this frame, like a synchronous read
                item = (None, exc)
            if not self._put(item) or item[1] is not None:
                return

    def _put(self, item: tuple[T | None, BaseException | None]) -> bool:
        """Blocks while the queue is full; False when asked to stop meanwhile."""
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=_POLL_S)
                return True
            except queue.Full:
                continue
        return False
