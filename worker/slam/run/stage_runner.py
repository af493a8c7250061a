"""The per-frame stages run on one frame, in order, with what they prepared ahead on another thread."""
from __future__ import annotations

from collections.abc import Callable

from worker.slam.io.prepare_ahead import Prepared
from worker.slam.io.sequence import Frame
from worker.slam.run.timer import StageTimer
from worker.slam.stages import FrameInputs, FrameStage, StageContext


class StageRunner:
    """`timings_ms[stage]` is the stage's compute time per frame (wherever it ran); `timings_ms[stage + '_wait']`
    what the pipeline thread waited for the prepared result; `overlapped` names the stages that ran ahead."""

    def __init__(self, stages: list[FrameStage], timer: StageTimer) -> None:
        self.stages, self.timer = stages, timer
        self.overlapped: set[str] = set()

    def preparers(self) -> dict[str, Callable[[Frame], object]]:
        """The stages' `prepare(frame)` functions (optional in the stage contract), by stage name."""
        out: dict[str, Callable[[Frame], object]] = {}
        for st in self.stages:
            prepare = getattr(st, "prepare", None)
            if callable(prepare):
                out[st.name] = prepare
        return out

    def process(self, item: Prepared, ctx: StageContext) -> tuple[FrameInputs, str | None]:
        """Run every stage on `item.frame` (timed as laps of `timer`); returns the frame's inputs and the name of
        the first stage that left deferred work in them (None: none did)."""
        inputs = FrameInputs()
        deferred_by = None
        for st in self.stages:
            ahead_ms = 0.0
            pending = item.pending.get(st.name)
            if pending is not None:
                inputs.prepared[st.name], ahead_ms = pending.result()  # a prepare error is raised here
                if inputs.prepared[st.name] is not None:  # None: nothing to do ahead (e.g. truth masks)
                    self.overlapped.add(st.name)
                self.timer.lap(f"{st.name}_wait")
            inputs = st.process(item.frame, inputs, ctx)
            self.timer.lap(st.name, ahead_ms)
            if inputs.deferred is not None and deferred_by is None:
                deferred_by = st.name
        return inputs, deferred_by

    def names(self) -> list[str]:
        return [st.name for st in self.stages]

    def history_frames(self) -> int:
        """The most past frames any stage reads from `StageContext.history` (its optional `history_frames`)."""
        return max((int(getattr(st, "history_frames", 0)) for st in self.stages), default=0)

    def summaries(self) -> dict[str, dict]:
        """Run-level figures of the stages that define `summary()`, by stage name, in stage order."""
        out = {}
        for st in self.stages:
            summary = getattr(st, "summary", None)
            if summary is not None:
                out[st.name] = summary()
        return out
