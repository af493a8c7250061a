"""Stage work deferred past tracking (restoration on demand), scheduled behind the pipeline thread.

A stage whose output tracking does not read may leave it in `FrameInputs.deferred`; it runs after tracking only
when the frame became a keyframe or a preview is due, and not before `FrameInputs.deferred_delay` later frames
went through the stages (restoration takes them for references), on a background thread (`WorkBehind`; its
results are stored in frame order, the same as in line), and its time is added to the stage's own entry for
that frame. The work gets the run's history as it was when the work was released (the frames after its target,
tracked), and its outputs go to the run's observer (the evaluation against truth) when it completes.
"""
from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from functools import partial

import numpy as np

from worker.slam.history import FrameHistory, HistoryView
from worker.slam.io.work_behind import WorkBehind
from worker.slam.run.frame_log import numbers
from worker.slam.run.previews import PreviewPicker
from worker.slam.stages import FrameInputs
from worker.slam.tracking.result import TrackResult

_Deferred = tuple[int, Callable[[HistoryView], float], Callable[[float], None]]
"""(frame index after whose stages the work may start, work given the history then, done), for
`WorkBehind.submit`."""

RestoredFn = Callable[[int, FrameInputs, np.ndarray | None], None]
"""`(frame index, its deferred outputs, its dynamic mask (H, W) bool or None)`: called when deferred work completes."""


class DeferredWork:
    """Per frame, on the pipeline thread: `offer` the frame's deferred work once it is tracked and mapped, then
    `release(index)` once frame `index` went through the stages; `finish()` after the last frame runs what is
    left and waits for it. `close()` (always, e.g. on an error) stops the background thread."""

    def __init__(self, behind: bool, previews: PreviewPicker, stride: int, history: FrameHistory,
                 on_done: RestoredFn | None = None) -> None:
        """`behind` False: the work runs on the pipeline thread when released; `stride`: the keyframes' image
        subsampling (`dense.stride`), for the restored images they get; `history`: the run's, viewed when work is
        released; `on_done`: told of each completed work's outputs (the evaluation against truth)."""
        self.previews, self.stride = previews, stride
        self.history, self.on_done = history, on_done
        self._behind = WorkBehind(behind)
        self._waiting: deque[_Deferred] = deque()  # by the frame index after which it may start

    def offer(self, inputs: FrameInputs, res: TrackResult, stage_ms: list[float], row: dict,
              stage_info: dict[str, list[float]]) -> None:
        """Queue the work a stage left in `inputs.deferred` when frame `res` became a keyframe or a preview is due
        (dropped otherwise: it holds the frame's images), to start `inputs.deferred_delay` frames later. When it
        is done: the keyframe gets the restored images the tracker would have stored had they been there when
        it tracked, the previews their slot (claimed now, in frame order, as if they had been offered now), the
        frame's figures its `row` and `stage_info`, and its time the stage's entry for this frame (the last of
        `stage_ms`)."""
        deferred, inputs.deferred = inputs.deferred, None
        why = "keyframe" if res.keyframe is not None else "preview" if self.previews.wants(res.index) else None
        if deferred is None or why is None:
            return
        keep_previews = self.previews.claim(res.index)
        out = FrameInputs(features=inputs.features)  # written by the background thread only
        hole = inputs.dynamic_mask
        entry = len(stage_ms) - 1

        def work(history: HistoryView) -> float:
            t0 = time.perf_counter()
            deferred(out, why, history)
            return (time.perf_counter() - t0) * 1000

        def done(ms: float) -> None:
            stage_ms[entry] += ms
            if res.keyframe is not None and out.restored_rgb is not None and out.restored_depth is not None:
                res.keyframe.set_dense_images(out.restored_rgb, out.restored_depth, self.stride)
            if keep_previews:
                self.previews.keep(res.index, out.previews or {})
            for key, val in numbers(out.info).items():
                stage_info[key].append(val)
                row[key] = out.info[key]
            if self.on_done is not None:
                self.on_done(res.index, out, hole)

        self._waiting.append((res.index + inputs.deferred_delay, work, done))

    def release(self, index: int) -> None:
        """Frame `index` went through the stages: start the work that waited for it, complete what finished."""
        while self._waiting and self._waiting[0][0] <= index:
            self._submit()
        self._behind.collect()

    def _submit(self) -> None:
        """Start the oldest waiting work with the history as it is now (read on this thread)."""
        _, work, done = self._waiting.popleft()
        self._behind.submit(partial(work, self.history.view()), done)

    def finish(self) -> None:
        """Start what still waits (the frames it waited for do not exist) and complete everything."""
        while self._waiting:
            self._submit()
        self._behind.finish()

    def close(self) -> None:
        self._behind.__exit__(None, None, None)
        self._waiting.clear()
