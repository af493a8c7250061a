"""Which spooled frame a live session runs next, and loading it ahead as soon as it arrives.

:class:`Follower` is the drop rule: the next frame is the oldest one not yet taken, unless more than
``max_behind`` wait (then the newest ``max_behind``; the older ones are dropped and counted). :class:`LiveFeed` takes
frames on its own thread the moment the run has room for one more (at most ``ahead`` frames taken ahead of the one
the run steps) and hands them over decoded, with their stages' `prepare` work already queued: while the pipeline
thread tracks frame k, the next frames are decoded and segmented as soon as they have arrived, not only once frame
k is done.
Frames are taken in arrival order and the drop rule is applied when a frame is taken, as the pipeline thread would.
"""
from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import Generic, TypeVar

from storage.live import LiveSpool, SpooledFrame, StreamEnd

log = logging.getLogger("worker.live")

T = TypeVar("T")
"""What the feed hands over per frame (the live runner's: the spooled frame and its `Prepared` frame)."""


class StreamEnded(Exception):
    """The spool ended (or went silent) before the next frame."""


class Follower:
    """The frames of ``spool`` in arrival order, dropping the oldest not taken when more than ``max_behind`` wait.
    Thread-safe: the feed thread takes frames while the pipeline thread reads the counts."""

    def __init__(self, spool: LiveSpool, max_behind: int, poll_s: float, idle_timeout_s: float) -> None:
        self.spool, self.max_behind = spool, max_behind
        self.poll_s, self.idle_timeout_s = poll_s, idle_timeout_s
        self.next_index = self.taken = self.dropped = 0
        self.end: StreamEnd | None = None
        self._lock = threading.Lock()  # the spool's reader state is not shared between threads unguarded

    @property
    def received(self) -> int:
        with self._lock:
            return self.spool.count()

    def counts(self, processed: int) -> dict[str, int]:
        """The session's counts, with ``processed`` frames stepped by the run."""
        return {"frames_received": self.received, "frames_processed": processed,
                "frames_dropped": self.dropped, "max_behind": self.max_behind}

    def skip_waiting(self) -> None:
        """Drop all but the newest ``max_behind`` frames received and not yet taken."""
        with self._lock:
            self._skip(self.spool.count())

    def _skip(self, n: int) -> None:
        if n - self.next_index > self.max_behind:
            self.dropped += n - self.max_behind - self.next_index
            self.next_index = n - self.max_behind

    def next(self, should_stop: Callable[[], bool] = lambda: False) -> SpooledFrame:
        """The next frame to run, waiting for it; raises :class:`StreamEnded` when the stream ended (or sent
        nothing for ``idle_timeout_s``: it is ended here) and every frame was taken, and when ``should_stop``."""
        quiet_since = time.monotonic()
        while True:
            with self._lock:
                n = self.spool.count()
                if n > self.next_index:
                    self._skip(n)
                    frame = self.spool.frame(self.next_index)
                    self.next_index += 1
                    self.taken += 1
                    return frame
                self.end = self.spool.ended()
                if self.end is not None and self.spool.count() <= self.next_index:
                    raise StreamEnded(self.end.reason)
                if time.monotonic() - quiet_since > self.idle_timeout_s:
                    self.end = self.spool.end(f"no frame for {self.idle_timeout_s:g} s", n)
                    log.warning("live session: %s; finishing with the frames received", self.end.reason)
                    raise StreamEnded(self.end.reason)
            if should_stop():
                raise StreamEnded("the run stopped following the stream")
            time.sleep(self.poll_s)


class LiveFeed(Generic[T]):
    """``load(frame)`` of each frame the follower gives, on one background thread, up to ``ahead`` frames ahead of
    the consumer: a frame is taken (and loaded) once it has arrived and fewer than ``ahead`` wait for the consumer.

    ``get(should_cancel)`` blocks for the next loaded frame; it raises :class:`StreamEnded` after the last one, the
    error that taking or loading a frame raised at that frame, and (checking ``should_cancel`` on the calling
    thread while it waits: a job's cancel check talks to the database, which is the pipeline thread's) whatever
    ``should_cancel`` raises. Use as a context manager: leaving stops the thread.
    """

    def __init__(self, follower: Follower, load: Callable[[SpooledFrame], T], poll_s: float = 0.05,
                 ahead: int = 1) -> None:
        if ahead < 1:
            raise ValueError(f"ahead must be at least 1, got {ahead}")
        self.follower, self.load, self.poll_s = follower, load, poll_s
        self._out: queue.Queue[tuple[T | None, BaseException | None]] = queue.Queue()
        self._room = threading.Semaphore(ahead)  # frames taken ahead of the consumer's
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="vtdslam-live-feed", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            if not self._room.acquire(timeout=self.poll_s):
                continue
            try:
                item = self.load(self.follower.next(self._stop.is_set))
            except BaseException as exc:  # noqa: BLE001 - handed to the consumer, raised there at this frame
                self._out.put((None, exc))
                return
            self._out.put((item, None))

    def get(self, should_cancel: Callable[[], object] = lambda: None) -> T:
        while True:
            try:
                item, exc = self._out.get(timeout=self.poll_s)
            except queue.Empty:
                should_cancel()
                continue
            if exc is not None:
                raise exc
            self._room.release()
            assert item is not None
            return item

    def __enter__(self) -> LiveFeed[T]:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
