"""The per-frame stage contract: what a stage gets and what it returns (a catalog, `worker.slam.catalog`, builds
stages by name; `formats.catalog.STAGE_CONTRACTS` says which `FrameInputs` fields each reads and fills).

A stage (segmentation, dynamic culling, restoration) runs before tracking. It gets the frame, the `FrameInputs`
built so far and a `StageContext` -- a narrow, read-only view of the run (camera, config, predicted and last
pose, the history of past frames, the sequence and its truth), never the tracker itself -- and returns updated
`FrameInputs`; the pipeline hands their `track_inputs()` to the tracker.

Two ways for a stage to keep work off the tracking path: `prepare(frame)` (work on the frame alone, run ahead
of the frame's turn on another thread; its result arrives in `FrameInputs.prepared`) and `FrameInputs.deferred`
(work whose output only keyframes and previews use, run after tracking when the frame turns out to need it).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from worker.slam.camera import Camera
from worker.slam.config import PipelineConfig
from worker.slam.features.types import Features
from worker.slam.history import HistoryView
from worker.slam.io.sequence import Frame, Sequence
from worker.slam.tracking.inputs import TrackInputs
from worker.slam.truth import Truth


@dataclass(frozen=True)
class ClassLabels:
    """A frame's segmentation classes as the later stages, the previews and the scores see them."""

    labels: np.ndarray
    """(H, W) uint8 indices into `classes` (0 = background)."""
    classes: tuple[str, ...]
    """The segmenter's class names."""
    dynamic_classes: tuple[str, ...]
    """The classes the run treats as potentially dynamic (a subset of `classes`)."""


@dataclass
class FrameInputs:
    """What the stages built for one frame (all optional; images are the frame's H,W). The fields are the
    products a stage contract (`formats.catalog.STAGE_CONTRACTS`) says a stage needs, uses or provides."""

    exclude_mask: np.ndarray | None = None
    """bool (H,W): True = pixel must not give features nor enter the dense map."""
    extra_features: Features | None = None
    """Keypoints to add to the frame's own (e.g. extracted in restored regions)."""
    restored_depth: np.ndarray | None = None
    """float32 metres (H,W): depth with removed regions filled; replaces the raw depth."""
    restored_rgb: np.ndarray | None = None
    """uint8 RGB (H,W,3): colour with removed regions filled; replaces the raw colour."""
    info: dict[str, float] = field(default_factory=dict)
    """Per-frame numbers a stage wants reported (e.g. {'dynamic_px': 1234}); their means land in
    metrics.json under `stage_info`."""
    features: Features | None = None
    """The frame's keypoints, already extracted (raw image coordinates) and culled: the tracker uses them
    instead of extracting its own."""
    potentially_dynamic: np.ndarray | None = None
    """bool (H,W): pixels of potentially dynamic classes (segmentation)."""
    class_labels: ClassLabels | None = None
    """The network's classes of the frame (segmentation; None for its truth source): previews colour by them."""
    dynamic_mask: np.ndarray | None = None
    """bool (H,W): pixels judged moving (culling)."""
    held_back: Features | None = None
    """Keypoints culling removed from `features`: the tracker falls back on them only when it would be lost."""
    extracted: Features | None = None
    """Every keypoint extracted from the frame, before culling (the history keeps them for later comparisons)."""
    culled: np.ndarray | None = None
    """bool (N,) over `extracted`: the keypoints culling removed after comparing the frame with a past one; None
    when it compared nothing (the first frame). Read by the evaluation against truth (`run.truth_observer`)."""
    previews: dict[str, np.ndarray] | None = None
    """RGB uint8 images worth saving for this frame (e.g. {'rgb', 'mask', 'restored'})."""
    prepared: dict[str, object] = field(default_factory=dict)
    """Results of stages' `prepare(frame)` computed ahead on another thread, by stage name; a stage whose entry
    is missing (or None) computes the same in `process`."""
    deferred: Callable[[FrameInputs, str, HistoryView], None] | None = None
    """Work a stage left for later because tracking does not read its output (restoration, when no keypoint's
    depth comes from restored pixels): `deferred(inputs, why, history)` (why: 'keyframe' or 'preview'; history:
    the run's history when the work was released, `deferred_delay` frames later) fills the frame's final inputs'
    `restored_rgb`, `restored_depth`, `previews` and `info` as `process` would have. The pipeline calls it after
    tracking only when the frame became a keyframe or a preview is due, and drops it otherwise."""
    deferred_delay: int = 0
    """Frames that must go through the stages after this one before `deferred` may run (e.g. restoration that
    takes the next frames, as tracked, for references)."""

    def track_inputs(self) -> TrackInputs:
        """The part the tracker reads."""
        return TrackInputs(features=self.features, exclude_mask=self.exclude_mask,
                           extra_features=self.extra_features, restored_depth=self.restored_depth,
                           restored_rgb=self.restored_rgb, held_back=self.held_back)


@dataclass(frozen=True)
class TrackedPose:
    """The last successfully tracked frame, as the stages see it."""

    index: int
    """Its frame index."""
    T_WC: np.ndarray
    """(4,4) float64 camera-to-world pose estimated for it."""
    covariance: np.ndarray | None
    """(6,6) of the T_CW left perturbation (rho, phi) from motion-only BA; None for the map's first frame."""


@dataclass(frozen=True)
class StageContext:
    """Everything a stage may read about the run; rebuilt before each frame's stages."""

    camera: Camera
    config: PipelineConfig
    sequence: Sequence | None
    """For reading neighbouring frames (random access, decoded on demand)."""
    truth: Truth | None = None
    """The sequence's ground truth of dynamic pixels and background (`truth/`), when it has one."""
    T_WC_pred: np.ndarray | None = None
    """(4,4) float64: the motion model's pose prediction for this frame; None before the first tracked frame."""
    last: TrackedPose | None = None
    """The last successfully tracked frame; None before the first."""
    history: HistoryView = HistoryView()
    """The frames before this one, as the stages left them and with their tracked poses (`worker.slam.history`);
    as many as the stages declare they read (`history_frames`)."""


class FrameStage(Protocol):
    """A per-frame stage. It may also define `summary() -> dict`: run-level figures that the pipeline stores in
    metrics.json under the stage's name; `prepare(frame) -> object`: work that depends on the frame alone
    (pure, deterministic, never touching what `process` changes), which the pipeline may run ahead on another
    thread and hands to `process` as `inputs.prepared[name]`; and `history_frames: int`: how many past frames it
    reads from `ctx.history` (none when absent)."""

    name: str

    def process(self, frame: Frame, inputs: FrameInputs, ctx: StageContext) -> FrameInputs: ...


StageFactory = Callable[[PipelineConfig, Camera], FrameStage]
"""Builds a stage for one run: `(config, camera) -> FrameStage`."""

