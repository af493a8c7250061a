"""Pipeline stage of the dynamic front end: (segmentation, in segmentation/stage.py →) culling (→ restoration,
in inpainting/stage.py).

The culling stage extracts the frame's ORB features once (the tracker reuses them), judges the objects against
a past frame (`lag_frames` back, from the run's history: its extracted features, depth and tracked pose) and hands
the tracker the features outside moving objects plus an exclude mask.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from formats.catalog import STAGE_CONTRACTS, provided_before
from worker.slam.camera import Camera
from worker.slam.config import PipelineConfig, valid
from worker.slam.dynamic.culling import CullingConfig, CullingResult, cull_frame, dilate_disc, mask_at
from worker.slam.features.orb import OrbExtractor
from worker.slam.features.types import Features
from worker.slam.geometry.se3 import inv
from worker.slam.history import PastFrame
from worker.slam.io.sequence import Frame
from worker.slam.stages import FrameInputs, StageContext


@dataclass
class CullingStageConfig:
    """Dynamic culling against the previous frame."""

    culling: CullingConfig = field(default_factory=CullingConfig)
    lag_frames: int = valid(10, 1, 1_000)
    """Compare with the frame this many frames back (the previous one at the start). Slow movers are the hard
    case: between consecutive frames a walking person's points move barely more than static points' noise, so
    a longer baseline separates them. Measured: docs/results/settings.md#culling-lag_frames"""
    min_kept_features: int = valid(0, 0, 100_000)
    """When culling would leave the tracker fewer features than this, keypoints in the exclusion band (near,
    not on, dynamic objects) are given back in the extractor's order (counted as `features_readmitted`). It
    rescues a wide band (`dilation_px` 15); with the narrow default band it was mixed and hurt `geometry-only`,
    so it is off. 0 = off. Measured: docs/results/settings.md#culling-min_kept_features"""
    refill_below: float = valid(0.5, 0.0, 1.0)
    """When culling leaves fewer than this share of `features.n_features`, the frame's keypoints are extracted
    again outside the exclusion mask and replace the kept ones (counted as `frames_refilled`): a textured
    person can take most of ORB's budget and leave the plain room around it few keypoints. Only frames culling
    compared (not the first), only with segmentation. 0 = off.
    Measured: docs/results/settings.md#culling-refill_below"""


class CullingStage:
    contract = STAGE_CONTRACTS["culling"]
    name = contract.name

    def __init__(self, config: PipelineConfig, camera: Camera) -> None:
        self.cfg: CullingStageConfig = config.section("culling")
        # Segmentation's mask is an optional input: used (if `culling.use_segmentation`, default on) when an
        # earlier stage provides it, else culling judges geometric clusters alone (`geometry-only`).
        self.use_segmentation = "potentially_dynamic" in provided_before(config.stages, self.name)
        self.camera = camera
        # its own extractor (the tracker's settings): `prepare` may run on another thread than the tracker's
        self.extractor = OrbExtractor(config.features)
        self.history_frames = max(1, self.cfg.lag_frames)
        """Past frames read from `ctx.history`: the one compared with is the oldest of them."""
        self.removed_total = self.kept_total = self.readmitted_total = self.refilled = 0
        self.compared = self.guided = self.not_judged = self.without_objects = self.marks_trusted = 0
        # semantic segments judged, and how many of them against their own (object-level) Δd
        self.segments_judged = self.object_thresholds = 0
        # Wall time of cull_frame alone (the stage also extracts the frame's ORB, which tracking needs anyway).
        # Not process CPU time: OpenCV's worker threads spin on an idle core and would inflate it.
        self.decision_ms: list[float] = []
        # This frame's result, None when nothing was compared (bench/plot_culling.py).
        self.last: CullingResult | None = None

    def prepare(self, frame: Frame) -> Features:
        """The frame's ORB features, from the frame alone: the pipeline may extract them ahead on another thread
        while the frame before is culled and tracked (the tracker uses them; it extracts nothing itself)."""
        return self._extract(frame)

    def _extract(self, frame: Frame, exclude: np.ndarray | None = None) -> Features:
        """The frame's ORB features outside `exclude` (H, W) bool, if given."""
        return self.extractor.extract(cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2GRAY), frame.depth, exclude)

    def process(self, frame: Frame, inputs: FrameInputs, ctx: StageContext) -> FrameInputs:
        self.last = None
        feats = inputs.prepared.get(self.name)
        if not isinstance(feats, Features):
            feats = self.prepare(frame)
        removed = np.zeros(len(feats), bool)
        history = ctx.history.recent(self.history_frames)
        compared = bool(history) and len(feats) > 0
        if compared:
            removed = self._cull(frame, inputs, ctx, feats, history[0])  # `lag_frames` back (the first at the start)
        elif self.use_segmentation and inputs.potentially_dynamic is not None and len(feats):
            # Nothing to compare with yet (first frame): keep potentially dynamic objects out of the new map.
            inputs.exclude_mask = dilate_disc(inputs.potentially_dynamic, self.cfg.culling.dilation_px)
            inputs.dynamic_mask = inputs.potentially_dynamic
            removed = mask_at(inputs.exclude_mask, feats.uv)
        self._hand_over(frame, inputs, feats, removed, compared)
        return inputs

    def _cull(self, frame: Frame, inputs: FrameInputs, ctx: StageContext, feats: Features,
              past: PastFrame) -> np.ndarray:
        """Which of the frame's features `feats` (N,) culling removes, bool (N,), judged against `past`; its masks
        and figures go into `inputs`, its counts into the stage's."""
        res = self._judge(frame, inputs, ctx, feats, past)
        removed = res.removed(feats.uv)
        removed = self._readmit(removed, feats.uv, res.dynamic_mask, inputs.info)
        self._count(res)
        self.last = res
        inputs.exclude_mask = res.exclude_mask
        inputs.dynamic_mask = res.dynamic_mask
        inputs.info.update(dynamic_fraction=float(res.dynamic_mask.mean()), threshold_px=res.threshold_px,
                           dynamic_segments=sum(s.dynamic for s in res.segments),
                           segments=len(res.segments),
                           object_thresholds=sum(s.object_level for s in res.segments), judged=res.judged)
        if res.entropy is not None:
            inputs.info["motion_entropy"] = res.entropy
        inputs.culled = removed
        return removed

    def _judge(self, frame: Frame, inputs: FrameInputs, ctx: StageContext, feats: Features,
               past: PastFrame) -> CullingResult:
        """`cull_frame` on the frame's features against the past frame's (with the motion predicted between
        them and the last tracked pose's covariance, where known); its wall time goes into `decision_ms`."""
        assert past.extracted is not None, "culling's own output: it runs on every frame"
        prev_feats, prev_depth = past.extracted, past.depth
        last = ctx.last
        cov = last.covariance if last is not None else None
        T_pred = ctx.T_WC_pred
        T_cur_prev = inv(T_pred) @ past.T_WC if T_pred is not None and past.T_WC is not None else None
        cfg = self.cfg.culling
        if not self.use_segmentation:
            cfg = dataclasses.replace(cfg, use_segmentation=False)
        t0 = time.perf_counter()
        res = cull_frame(prev_feats.uv, prev_feats.desc, feats.uv, feats.desc, frame.depth,
                         inputs.potentially_dynamic if self.use_segmentation else None, cov, cfg,
                         prev_depth, self.camera.K, T_cur_prev)
        self.decision_ms.append(1000 * (time.perf_counter() - t0))
        return res

    def _count(self, res: CullingResult) -> None:
        """Add a compared frame's result to the run-level counts (`summary`)."""
        self.compared += 1
        self.guided += res.guided
        self.not_judged += not res.judged
        self.without_objects += res.without_objects
        self.marks_trusted += res.marks_trusted
        if res.judged and not res.marks_trusted:  # trusted marks are excluded unjudged (`judge_marks_above`)
            self.segments_judged += sum(s.kind == "semantic" for s in res.segments)
        self.object_thresholds += sum(s.object_level for s in res.segments)

    def _hand_over(self, frame: Frame, inputs: FrameInputs, feats: Features, removed: np.ndarray,
                   compared: bool) -> None:
        """Give the tracker the features `feats` not `removed` (N,) bool -- extracted again outside the exclusion
        mask when culling left too few -- and the removed ones held back; count them."""
        inputs.features = feats.select(~removed)
        starved = (~removed).sum() < self.cfg.refill_below * self.extractor.cfg.n_features
        # only frames culling compared: a first frame's exclusion is the unjudged network mask, and a map started
        # on the few keypoints outside it finds too few of them in the next frame (the 90 %-masked test lost frame 1)
        if self.use_segmentation and compared and starved:
            inputs.features = self._extract(frame, inputs.exclude_mask)
            inputs.info["features_refilled"] = len(inputs.features)
            self.refilled += 1
        inputs.held_back = feats.select(removed) if removed.any() else None
        inputs.info.update(features_removed=int(removed.sum()), features_kept=int((~removed).sum()))
        self.removed_total += int(removed.sum())
        self.kept_total += int((~removed).sum())
        inputs.extracted = feats

    def _readmit(self, removed: np.ndarray, uv: np.ndarray, dynamic: np.ndarray, info: dict) -> np.ndarray:
        """`removed` (N,) with band keypoints (removed, not on `dynamic` (H, W)) given back up to the minimum."""
        short = self.cfg.min_kept_features - int((~removed).sum())
        if short <= 0:
            return removed
        band = np.flatnonzero(removed & ~mask_at(dynamic, uv))[:short]
        removed = removed.copy()
        removed[band] = False
        info["features_readmitted"] = len(band)
        self.readmitted_total += len(band)
        return removed

    def summary(self) -> dict:
        """Run-level figures (the evaluation against truth adds its "truth" entry: `run.truth_observer`)."""
        return {"features_removed": self.removed_total, "features_kept": self.kept_total,
                "features_readmitted": self.readmitted_total, "frames_refilled": self.refilled,
                "frames_compared": self.compared, "guided_matching_frames": self.guided,
                "frames_not_judged": self.not_judged, "frames_without_objects": self.without_objects,
                "frames_marks_trusted": self.marks_trusted,
                "segments_judged": self.segments_judged, "object_level_thresholds": self.object_thresholds,
                "decision_ms_median": float(np.median(self.decision_ms)) if self.decision_ms else None}
