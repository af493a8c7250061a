"""Frames of a sequence fed to a run with the work around the pipeline thread overlapped.

Frames are decoded ahead on a background thread (`read_ahead`), and the stages' `prepare(frame)` (the
segmentation network) run ahead on another (`prepare_ahead`), so frame k+1 is segmented while frame k is culled
and tracked; the run's deferred stage work runs behind it on a third (`PipelineRun(restore_behind=...)`).
Results are the same either way: each thread works in frame order and the run consumes its results in order.
`timings_ms['read']` is what the pipeline thread waited for the decoded frame.
"""
from __future__ import annotations

from collections.abc import Iterator
from itertools import chain

from worker.slam.io.prepare_ahead import PrepareAhead, Prepared
from worker.slam.io.read_ahead import ReadAhead
from worker.slam.io.sequence import Frame, Sequence
from worker.slam.run.callbacks import CancelFn, PipelineCancelled
from worker.slam.run.pipeline_run import PipelineRun


def drive(run: PipelineRun, sequence: Sequence, first: Frame, rest: range, *, read_ahead: int = 2,
          prepare_ahead: bool = True, should_cancel: CancelFn | None = None) -> None:
    """`run.step` on `first` (already read: it fixed the camera size), then on frames `rest` of `sequence`.

    `read_ahead`: frames decoded ahead on a background thread (0: read on this thread). `prepare_ahead`: with
    read-ahead, run the stages' `prepare(frame)` on another background thread as frames are decoded (False, or
    `read_ahead` 0: each stage computes it in `process` on this thread). `should_cancel` is checked before every
    frame; True raises `PipelineCancelled`. Leaving (also by an error) stops both threads; the caller then
    calls `run.finish()` (or closes the run).
    """
    total = 1 + len(rest)
    # the reader queues each decoded frame's `prepare` work on the second thread (left by `with` before the
    # reader stops)
    with PrepareAhead(run.stages.preparers() if prepare_ahead and read_ahead > 0 else {}) as prep, \
            ReadAhead(lambda i: prep.submit(sequence[i]), rest, read_ahead) as ahead:
        frames: Iterator[Prepared] = chain([prep.submit(first)], ahead)
        for k in range(total):
            if should_cancel is not None and should_cancel():
                raise PipelineCancelled(f"cancelled after {k} of {total} frames")
            run.timer.mark()
            item = next(frames)  # with read-ahead: the wait for the reader thread, not the decoding
            run.timer.lap("read")
            run.step(item)
