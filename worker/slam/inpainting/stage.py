"""Pipeline stage: restore the background behind culled objects from recent frames, then find features there.

Online: references come from the last `window` frames, whose poses the tracker has already estimated; the
target's own pose is the motion model's prediction (PatchMatch absorbs its small error). The restored RGB and
depth replace the raw frame for keypoint depth and the dense map, and ORB keypoints found in the restored region
(strong response, confident depth, seen by a reference) are handed to the tracker as extra features.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import cv2
import numpy as np

from worker.slam.camera import Camera
from worker.slam.config import PipelineConfig
from worker.slam.features.types import Features
from worker.slam.inpainting.references import Candidate, ReferenceSelectionConfig, select_references
from worker.slam.inpainting.restore import ReferenceView, Restoration, RestorationConfig, restore_frame
from worker.slam.io.sequence import Frame
from worker.slam.stages import FrameInputs, StageContext
from worker.slam.truth import restoration_psnr


@dataclass
class RestorationStageConfig:
    """Background restoration inside the live pipeline."""

    references: ReferenceSelectionConfig = field(default_factory=ReferenceSelectionConfig)
    restoration: RestorationConfig = field(default_factory=RestorationConfig)
    restored_features: bool = False
    """Extract ORB keypoints in restored regions and give them to the tracker. Off by default: they raise ATE
    many times over. Online, the target is warped at the motion model's *predicted* pose, so features found in
    the restored region agree with the prediction and pull the estimate towards it instead of correcting it."""
    min_response_quantile: float = 0.5
    """Restored keypoints must respond at least as strongly as this quantile of the frame's own keypoints."""
    min_depth_confidence: float = 0.5
    """Restored keypoints need restored depth at least this confident."""
    min_hole_fraction: float = 0.001
    """Holes smaller than this fraction of the image are not worth restoring."""
    previews: int = 6
    """Frames whose raw / mask / restored images are kept as preview artifacts."""


@dataclass
class _Past:
    index: int
    rgb: np.ndarray
    depth: np.ndarray
    dynamic: np.ndarray
    desc: np.ndarray | None
    T_WC: np.ndarray | None = None


class RestorationStage:
    name = "restoration"

    def __init__(self, config: PipelineConfig, camera: Camera) -> None:
        self.cfg: RestorationStageConfig = config.section("restoration")
        self.camera = camera
        self.past: deque[_Past] = deque(maxlen=self.cfg.references.window)
        self.psnr: list[float] = []
        self.depth_err: list[float] = []
        self.restored_frames = 0
        self.extra = 0
        self.relaxed = 0

    def _record_pose(self, ctx: StageContext) -> None:
        last = ctx.last
        if last is None:
            return
        for p in self.past:
            if p.index == last.index:
                p.T_WC = last.T_WC.copy()

    def process(self, frame: Frame, inputs: FrameInputs, ctx: StageContext) -> FrameInputs:
        self._record_pose(ctx)
        hole = inputs.dynamic_mask if inputs.dynamic_mask is not None else np.zeros(frame.depth.shape, bool)
        desc = inputs.features.desc if inputs.features is not None else None
        if hole.mean() >= self.cfg.min_hole_fraction:
            self._restore(frame, hole, desc, inputs, ctx)
        self.past.append(_Past(frame.index, frame.rgb, frame.depth, hole, desc))
        return inputs

    def _restore(self, frame: Frame, hole: np.ndarray, desc: np.ndarray | None, inputs: FrameInputs,
                 ctx: StageContext) -> None:
        T_pred = ctx.T_WC_pred
        if T_pred is None:  # before the first tracked frame there is no pose to warp into
            return
        posed = [(p, p.T_WC) for p in self.past if p.T_WC is not None]
        sel = select_references(Candidate(frame.index, T_pred, desc),
                                [Candidate(p.index, T_WC, p.desc) for p, T_WC in posed], self.cfg.references)
        self.relaxed += int(sel.relaxed)
        by_index = {p.index: (p, T_WC) for p, T_WC in posed}
        refs = [ReferenceView(p.rgb, p.depth, T_WC, p.dynamic) for p, T_WC in (by_index[i] for i in sel.indices)]
        out = restore_frame(frame.rgb, frame.depth, hole, T_pred, refs, self.camera.K, self.cfg.restoration)
        inputs.restored_rgb, inputs.restored_depth = out.rgb, out.depth
        self.restored_frames += 1
        inputs.info.update(references=len(refs), hole_fraction=float(hole.mean()),
                           hole_seen_fraction=float(out.seen_by_reference.sum() / max(hole.sum(), 1)))
        if self.cfg.restored_features:
            extra = self._restored_features(out, hole, inputs.features, ctx)
            inputs.extra_features = extra
            self.extra += len(extra)
            inputs.info["restored_features"] = len(extra)
        inputs.previews = {"rgb": frame.rgb, "mask": _overlay(frame.rgb, hole), "restored": out.rgb}
        truth = ctx.truth
        if truth is not None and frame.index < len(truth):
            self.psnr.append(min(restoration_psnr(out.rgb, truth.background_rgb(frame.index), hole), 100.0))
            bg = truth.background_depth(frame.index)
            ok = hole & (out.depth > 0) & (bg > 0)
            if ok.any():
                self.depth_err.append(float(np.median(np.abs(out.depth[ok] - bg[ok]))))

    def _restored_features(self, out: Restoration, hole: np.ndarray, own: Features | None,
                           ctx: StageContext) -> Features:
        region = cv2.dilate(hole.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        gray = cv2.cvtColor(out.rgb, cv2.COLOR_RGB2GRAY)
        feats = ctx.extractor.extract(gray, out.depth, ~region)
        if not len(feats):
            return feats
        h, w = hole.shape
        x = np.clip(np.rint(feats.uv[:, 0]).astype(int), 0, w - 1)
        y = np.clip(np.rint(feats.uv[:, 1]).astype(int), 0, h - 1)
        keep = (out.depth_confidence[y, x] >= self.cfg.min_depth_confidence) & out.seen_by_reference[y, x]
        if own is not None and len(own):
            keep &= feats.response >= np.quantile(own.response, self.cfg.min_response_quantile)
        return feats.select(keep)

    def summary(self) -> dict:
        out: dict = {"restored_frames": self.restored_frames, "restored_features": self.extra,
               "relaxed_reference_choices": self.relaxed}
        if self.psnr:
            out["truth"] = {"restoration_psnr": float(np.mean(self.psnr)),
                            "restoration_depth_median_m": float(np.median(self.depth_err)) if self.depth_err
                            else None}
        return out


def _overlay(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    out = rgb.copy()
    out[mask] = (0.5 * out[mask] + 0.5 * np.array([255, 40, 40])).astype(np.uint8)
    return out
