"""The one place the worker calls the SLAM pipeline (``worker.slam``), so its signature is matched here only.

:func:`run_slam` is the adapter: a sequence folder, the sequence's stored camera spec, a preset and
config overrides, an output folder and two callbacks in; the pipeline's files in ``out_dir`` and a
:class:`RunOutput` out. Tests inject any function with the same signature (:data:`PipelineFn`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from formats.frame_stats import FrameStats

ProgressFn = Callable[[int, int, str], None]
"""(frames_done, frames_total, stage)."""
CancelFn = Callable[[], bool]
"""True when the run should stop (checked by the pipeline before every frame)."""

class Cancelled(Exception):
    """The run stopped because its cancel check said so."""


@dataclass
class RunOutput:
    metrics: dict[str, Any]
    """The run's metrics: the content of ``metrics.json`` (formats.run_metrics.RunMetrics reads it)."""
    config: dict[str, Any]
    """The full config snapshot the run used."""
    frame_stats: list[FrameStats] = field(default_factory=list)
    """Per frame, as the service stores them."""


class PipelineFn(Protocol):
    def __call__(
        self,
        sequence_dir: Path,
        camera: dict[str, Any],
        preset: str,
        overrides: dict[str, Any],
        out_dir: Path,
        *,
        progress: ProgressFn,
        should_cancel: CancelFn,
    ) -> RunOutput: ...


def run_slam(
    sequence_dir: Path,
    camera: dict[str, Any],
    preset: str,
    overrides: dict[str, Any],
    out_dir: Path,
    *,
    progress: ProgressFn,
    should_cancel: CancelFn,
    snapshot: Callable[..., None] | None = None,
) -> RunOutput:
    """Run ``worker.slam`` on a sequence folder, writing trajectory.txt, keyframes.txt, map.ply,
    metrics.json and config.json into ``out_dir``.

    ``camera`` is what ``Sequence.camera`` stores: ``{"preset": name}`` or explicit intrinsics (a
    ``camera.json`` in the folder wins, as everywhere). Raises :class:`Cancelled` when ``should_cancel``
    stopped it and ``worker.slam.errors.SlamError`` on bad input or configuration. ``snapshot``: the run's
    ``on_step`` hook (``worker.snapshots.PartialWriter``: partial results while it runs).
    """
    from worker.slam.camera import Camera, camera_from_preset
    from worker.slam.io.sequence import Sequence
    from worker.slam.pipeline import PipelineCancelled, run_pipeline
    from worker.slam.presets import get_preset

    cam = camera_from_preset(camera["preset"]) if "preset" in camera else Camera.from_dict(camera)
    config = get_preset(preset, overrides or None)
    sequence = Sequence(sequence_dir, cam)
    try:
        result = run_pipeline(sequence, config, out_dir, progress=progress, should_cancel=should_cancel,
                              on_step=snapshot)
    except PipelineCancelled as exc:
        raise Cancelled(exc.message) from exc
    frame_stats = [FrameStats.from_row(r) for r in result.frame_stats]
    return RunOutput(metrics=result.metrics, config=config.to_dict(), frame_stats=frame_stats)
