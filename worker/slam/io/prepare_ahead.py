"""Per-frame work that depends on the frame alone, run on background threads ahead of the frame's turn.

A stage's `prepare(frame)` (segmentation: the network's mask from the RGB; culling: the frame's ORB features)
needs nothing from earlier frames, so it can run while the pipeline thread culls and tracks the frame before.
Each stage's `prepare` has its own thread, so the segmentation of a frame and its ORB extraction run side by
side (both release the GIL in their native code) instead of one after the other: on one thread their sum was the
slowest lane of a live session (docs/results/realtime.md). The overlap is limited by the GIL: MSNET's forward
pass releases it only in part (same file, "Pipelined worker: segmentation ahead, restoration on demand").
Each thread is fed in frame order: each result is what the pipeline thread would have computed (the same
function on the same frame), and a model is never called by two threads at once.
Each result comes with its compute time, so the pipeline reports the stage's cost and, apart from it, how long
it waited for the result.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from types import TracebackType

from worker.slam.io.sequence import Frame

THREAD_NAME = "vtdslam-prepare"


@dataclass(frozen=True)
class Prepared:
    """A frame with its pending results: futures of (result, compute ms) by name (empty: nothing ahead)."""

    frame: Frame
    pending: Mapping[str, Future[tuple[object, float]]] = field(default_factory=dict)


def _timed(fn: Callable[[Frame], object], frame: Frame) -> tuple[object, float]:
    t0 = time.perf_counter()
    out = fn(frame)
    return out, 1000 * (time.perf_counter() - t0)


class PrepareAhead:
    """`submit(frame)` queues every `prepare` function on the frame, each on its own thread; with none, no thread
    is started.

    Use as a context manager: leaving it cancels what has not started and waits for what runs (at most one
    frame's work per stage), so an error or a cancellation in the consumer stops the threads. Submitting is thread-safe
    (the read-ahead thread submits the frames it has decoded).
    """

    def __init__(self, prepare: Mapping[str, Callable[[Frame], object]]) -> None:
        self._prepare = dict(prepare)
        self._pools = {name: ThreadPoolExecutor(1, thread_name_prefix=f"{THREAD_NAME}-{name}")
                       for name in self._prepare}

    @property
    def names(self) -> list[str]:
        """What runs ahead, by name."""
        return list(self._prepare)

    def submit(self, frame: Frame) -> Prepared:
        return Prepared(frame, {name: self._pools[name].submit(_timed, fn, frame)
                                for name, fn in self._prepare.items()})

    def __enter__(self) -> PrepareAhead:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        for pool in self._pools.values():  # every queue cancelled first, then each thread waited for
            pool.shutdown(wait=False, cancel_futures=True)
        for pool in self._pools.values():
            pool.shutdown(wait=True)
