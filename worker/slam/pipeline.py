"""Run a sequence through the pipeline: `run_pipeline`, the entry point of the worker, the CLI and the benches.

A thin function over the run object (`worker.slam.run`): it reads the first frame (which fixes the camera size),
builds the config's stages, makes a `PipelineRun`, feeds it the frames with reading, the stages' `prepare` work
and deferred stage work overlapped on background threads (`run.driver`), finishes it and writes the outputs.
"""
from __future__ import annotations

from pathlib import Path

from worker.slam.catalog import shipped_catalog
from worker.slam.config import PipelineConfig
from worker.slam.errors import ConfigError
from worker.slam.io.sequence import Sequence
from worker.slam.run.callbacks import CancelFn, PipelineCancelled, ProgressFn
from worker.slam.run.driver import drive
from worker.slam.run.outputs import write_outputs
from worker.slam.run.pipeline_run import PipelineRun, StepFn
from worker.slam.run.result import RunResult
from worker.slam.stages import FrameStage
from worker.slam.truth import load_truth

__all__ = ["CancelFn", "PipelineCancelled", "ProgressFn", "RunResult", "run_pipeline", "write_outputs"]


def run_pipeline(sequence: Sequence, config: PipelineConfig, out_dir: Path | str | None = None, *,
                 start: int = 0, max_frames: int | None = None, progress: ProgressFn | None = None,
                 should_cancel: CancelFn | None = None, stages: list[FrameStage] | None = None,
                 read_ahead: int = 2, prepare_ahead: bool = True, restore_behind: bool = True,
                 on_step: StepFn | None = None) -> RunResult:
    """Track frames [start, start+max_frames) of `sequence`; write the outputs to `out_dir` when given.

    `stages`: the per-frame stages to run (default: those `config.stages` names). `read_ahead`,
    `prepare_ahead`: see `run.driver.drive`; `restore_behind`: see `PipelineRun`.
    """
    if start < 0 or start >= len(sequence):
        raise ConfigError(f"start {start} is outside the sequence (0..{len(sequence) - 1})")
    stop = len(sequence) if max_frames is None else min(len(sequence), start + max(0, max_frames))
    total = stop - start
    first = sequence[start]  # also fixes the camera size (Sequence rescales it on first read)
    camera = sequence.camera
    stages = shipped_catalog().build_stages(config, camera) if stages is None else stages
    with PipelineRun(camera, config, stages, sequence=sequence, truth=load_truth(sequence.root), start=start,
                     total=total, progress=progress, restore_behind=restore_behind, on_step=on_step) as run:
        drive(run, sequence, first, range(start + 1, stop), read_ahead=read_ahead, prepare_ahead=prepare_ahead,
              should_cancel=should_cancel)
        result = run.finish()
    if out_dir is not None:
        if progress is not None:
            progress(total, total, "writing")
        write_outputs(result, config, Path(out_dir))
    return result
