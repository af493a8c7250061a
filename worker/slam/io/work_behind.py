"""Work the pipeline thread hands off once a frame is tracked, run on one background thread behind it.

Restoration of keyframes and previews (`FrameInputs.deferred`) only fills images that nothing reads before the
run ends (the dense map, the previews), so the pipeline thread need not wait for it: it goes on with the next
frame while the restoration runs here. Each piece of work comes with a `done` step that the pipeline thread
runs, in submission order, once the work has finished (storing the images and the frame's figures), so the
outputs are those of running everything in line. At most `max_pending` pieces wait; a further one first
completes the oldest, which bounds the memory held by queued frames.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from types import TracebackType
from typing import Any

THREAD_NAME = "vtdslam-behind"


class WorkBehind:
    """`submit(work, done)`: `work()` on the background thread (here, at once, when `enabled` is False), then
    `done(result)` on the caller's thread in submission order, from a later `submit`, `collect` or `finish`.

    Use as a context manager: leaving it cancels work not started and waits for the running one, so an error or
    a cancellation on the pipeline thread stops the background thread too.
    """

    def __init__(self, enabled: bool = True, max_pending: int = 4) -> None:
        self.max_pending = max(1, max_pending)
        self._pool = ThreadPoolExecutor(1, thread_name_prefix=THREAD_NAME) if enabled else None
        self._pending: deque[tuple[Future[Any], Callable[[Any], None]]] = deque()

    @property
    def enabled(self) -> bool:
        return self._pool is not None

    def submit(self, work: Callable[[], Any], done: Callable[[Any], None]) -> None:
        if self._pool is None:
            done(work())
            return
        self._pending.append((self._pool.submit(work), done))
        self.collect(wait_for=len(self._pending) - self.max_pending)

    def collect(self, wait_for: int = 0) -> None:
        """Run the `done` steps of finished work, oldest first, stopping at the first unfinished one; the
        oldest `wait_for` pieces are waited for. A failure in the work is raised here."""
        while self._pending and (wait_for > 0 or self._pending[0][0].done()):
            future, done = self._pending.popleft()
            done(future.result())
            wait_for -= 1

    def finish(self) -> None:
        """Wait for all submitted work and complete it."""
        self.collect(wait_for=len(self._pending))

    def __enter__(self) -> WorkBehind:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        self._pending.clear()
