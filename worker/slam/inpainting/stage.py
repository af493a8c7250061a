"""Pipeline stage: restore the background behind culled objects from neighbouring frames, then find features there.

References (`references`): "causal" takes them from the last `window` frames, whose poses the tracker has
already estimated and whose moving pixels culling has marked (streaming input has nothing else); "both-sided"
(a job's uploaded sequence) adds the next `window` frames. Second-chance references come from up to
`far_window` frames away (`selection.far_refs`). A deferred restoration (below) waits until the frames after
its target have been tracked and takes them like the past ones, with the target at its own tracked pose
(`deferred_future: tracked`); one that tracking reads at once reads the next `window` frames ahead through the
sequence (no far future ones), with pose and moving pixels estimated against the target by geometry
(`lookahead`), and the target at the motion model's prediction (geometry-first copying and PatchMatch absorb
its small error). The restored RGB and
depth replace the raw frame for keypoint depth and the dense map, and ORB keypoints found in the restored region
(strong response, confident depth, seen by a reference) are handed to the tracker as extra features.

On demand (`on_demand`, the default): tracking reads restored pixels only through restored features (off by
default) and through the depth looked up at keypoints whose few-pixel neighbourhood reaches into the hole. A
frame with neither is not restored in `process`: its restoration is left in `FrameInputs.deferred`, which the
pipeline runs only when the frame becomes a keyframe (the dense map) or a preview is due, on a background
thread while the next frames are tracked. Outputs are the same; the restoration metrics then cover the restored
frames only (`restored_frames`, `restored_for`). A restoration reads only what `process` captured for it (the
frame, its hole, the past references as they were), the run's history when it was released (the frames after
its target, as tracked) and the stage's state that only restorations touch, under one lock, so one in `process`
and one deferred never interleave. Past and future references are records of the run's history
(`worker.slam.history`); the stage keeps no frames of its own but the ones it read ahead.
"""
from __future__ import annotations

import threading
from collections import Counter
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from formats.catalog import STAGE_CONTRACTS
from worker.slam.camera import Camera
from worker.slam.config import PipelineConfig, valid
from worker.slam.features.orb import OrbExtractor
from worker.slam.features.types import Features
from worker.slam.history import HistoryView, PastFrame
from worker.slam.inpainting.lookahead import LookaheadConfig, moving_pixels, relative_pose_pnp
from worker.slam.inpainting.references import Candidate, ReferenceSelectionConfig, select_references
from worker.slam.inpainting.restore import ReferenceView, Restoration, RestorationConfig, restore_frame
from worker.slam.io.sequence import Frame
from worker.slam.stages import FrameInputs, StageContext


@dataclass
class RestorationStageConfig:
    """Background restoration inside the live pipeline."""

    reference_margin_px: int = valid(8, 0, 100)
    """Each reference's moving pixels are widened by this many pixels before anything is copied from it: the
    segmentation's masks miss a person's fringe (hair, a hand, the outline of a coarse mask), and a reference
    copies that fringe into the hole. 0 = off. Measured: docs/results/settings.md#restoration-reference_margin_px"""
    references: str = "both-sided"
    """Where reference frames come from: "both-sided" (the `window` frames before and after the target; for
    jobs, which have the whole sequence) or "causal" (only the frames before; for streaming input)."""
    selection: ReferenceSelectionConfig = field(default_factory=ReferenceSelectionConfig)
    lookahead: LookaheadConfig = field(default_factory=LookaheadConfig)
    restoration: RestorationConfig = field(default_factory=RestorationConfig)
    restored_features: bool = False
    """Extract ORB keypoints in restored regions and give them to the tracker. Off by default: they raise ATE
    many times over. Online, the target is warped at the motion model's *predicted* pose, so features found in
    the restored region agree with the prediction and pull the estimate towards it instead of correcting it."""
    min_response_quantile: float = valid(0.5, 0.0, 1.0)
    """Restored keypoints must respond at least as strongly as this quantile of the frame's own keypoints."""
    min_depth_confidence: float = valid(0.5, 0.0, 1.0)
    """Restored keypoints need restored depth at least this confident."""
    min_hole_fraction: float = valid(0.001, 0.0, 1.0)
    """Holes smaller than this fraction of the image are not worth restoring."""
    previews: int = valid(6, 0, 1_000)
    """Frames whose raw / mask / restored images are kept as preview artifacts."""
    on_demand: bool = True
    """Restore only frames whose restored images something uses: keyframes (the dense map), preview frames and
    frames whose keypoint depth would come from restored pixels (always, with `restored_features`). The others'
    restoration changed no output but the restoration metrics, and cost most of the frame's time. False:
    every frame with a hole is restored (the restoration metrics then cover all of them)."""

    deferred_future: str = "tracked"
    """Future references of a deferred restoration (a keyframe's or a preview's: nothing reads them before the run
    ends), with "both-sided": "tracked" waits until the next `selection.reach` frames have been tracked and takes
    them as the past ones are taken (the tracker's poses, culling's moving pixels), with the target at its own tracked
    pose; "lookahead" reads them ahead, poses them by PnP against the target at its predicted pose and finds
    their moving pixels by geometry, as a restoration that tracking reads at once always does."""

    def __post_init__(self) -> None:
        if self.references not in ("causal", "both-sided"):
            raise ValueError(f"references must be 'causal' or 'both-sided', not {self.references!r}")
        if self.deferred_future not in ("tracked", "lookahead"):
            raise ValueError(f"deferred_future must be 'tracked' or 'lookahead', not {self.deferred_future!r}")


class RestorationStage:
    contract = STAGE_CONTRACTS["restoration"]
    name = contract.name

    def __init__(self, config: PipelineConfig, camera: Camera) -> None:
        self.cfg: RestorationStageConfig = config.section("restoration")
        self.camera = camera
        reach = self.cfg.selection.reach
        self.tracked_future = self.cfg.references == "both-sided" and self.cfg.deferred_future == "tracked"
        """Deferred restorations take the frames after the target from the history, as tracked."""
        self.history_frames = reach + 2 if self.tracked_future else reach
        """Past frames read from `ctx.history`: `reach` references before the target; a deferred restoration
        released `reach` + 1 frames after its target also reads the target and the `reach` frames after it."""
        self.ahead: dict[int, tuple[Frame, Features]] = {}
        """Future frames read for both-sided references, with their ORB features, by index."""
        self.future_refs = 0
        self.far_refs = 0
        self.restored_frames = 0
        self.restored_for: Counter[str] = Counter()
        """Why frames were restored: 'tracking' (in `process`), 'keyframe' or 'preview' (deferred)."""
        self.deferred = 0
        self.extra = 0
        self.relaxed = 0
        self.references_used = 0
        self.poses_refined = 0  # references whose pose the photometric alignment corrected
        # restorations may run on the pipeline's background thread: they share `ahead`, the counters and an
        # extractor of their own (not the tracker's)
        self._lock = threading.Lock()
        self.extractor = OrbExtractor(config.features)

    def process(self, frame: Frame, inputs: FrameInputs, ctx: StageContext) -> FrameInputs:
        hole = inputs.dynamic_mask if inputs.dynamic_mask is not None else np.zeros(frame.depth.shape, bool)
        desc = inputs.features.desc if inputs.features is not None else None
        reach = self.cfg.selection.reach
        # before the first tracked frame there is no pose to warp into
        if hole.mean() >= self.cfg.min_hole_fraction and ctx.T_WC_pred is not None:
            past = ctx.history.recent(reach)  # immutable records: a deferred call sees them as they are now
            inputs.info["hole_fraction"] = float(hole.mean())  # every frame with a hole, restored or not
            if self.cfg.on_demand and not self._tracking_reads(hole, inputs, ctx):
                self.deferred += 1
                tracked = self.tracked_future
                if tracked:
                    inputs.deferred_delay = reach + 1  # until the last future frame has its pose

                def deferred(out: FrameInputs, why: str, later: HistoryView) -> None:
                    self._restore(frame, hole, desc, out, ctx, past, why, later if tracked else None)

                inputs.deferred = deferred
            else:
                self._restore(frame, hole, desc, inputs, ctx, past, "tracking")
        return inputs

    def _tracking_reads(self, hole: np.ndarray, inputs: FrameInputs, ctx: StageContext) -> bool:
        """Whether the tracker would read any restored pixel of this frame: restored features, no features of
        the stages' own (it extracts from the restored RGB), or a keypoint whose depth lookup (2x2 bilinear,
        nearest pixel, `depth_edge_radius_px` window: `features.depth.lookup_depth`) touches the hole, the
        only pixels restoration changes."""
        feats = inputs.features
        if self.cfg.restored_features or feats is None:
            return True
        if not len(feats):
            return False
        h, w = hole.shape
        r = ctx.config.features.depth_edge_radius_px
        x0 = np.clip(feats.uv[:, 0], 0, w - 1.001).astype(int)
        y0 = np.clip(feats.uv[:, 1], 0, h - 1.001).astype(int)
        # hole pixels in the box [x0 - r, x0 + 1 + r] x [y0 - r, y0 + 1 + r] (clipped), by an integral image
        cum = cv2.integral(hole.astype(np.uint8))
        xa, xb = np.clip(x0 - r, 0, w), np.clip(x0 + 2 + r, 0, w)
        ya, yb = np.clip(y0 - r, 0, h), np.clip(y0 + 2 + r, 0, h)
        return bool(np.any(cum[yb, xb] - cum[ya, xb] - cum[yb, xa] + cum[ya, xa] > 0))

    def _restore(self, frame: Frame, hole: np.ndarray, desc: np.ndarray | None, inputs: FrameInputs,
                 ctx: StageContext, past: tuple[PastFrame, ...], why: str, later: HistoryView | None = None) -> None:
        """`later`: the run's history when a deferred restoration ("tracked" future) was released."""
        with self._lock:
            self._restore_locked(frame, hole, desc, inputs, ctx, past, why, later)

    def _restore_locked(self, frame: Frame, hole: np.ndarray, desc: np.ndarray | None, inputs: FrameInputs,
                        ctx: StageContext, past: tuple[PastFrame, ...], why: str, later: HistoryView | None) -> None:
        T_target = ctx.T_WC_pred
        assert T_target is not None
        both = self.cfg.references == "both-sided"
        views: dict[int, ReferenceView] = {}
        cands: list[Candidate] = []
        if later is not None:
            # the target where the tracker put it (if it was tracked), and the frames after it as tracked
            own = later.get(frame.index)
            T_target = own.T_WC if own is not None and own.T_WC is not None else T_target
            past = (*past, *later.between(frame.index + 1, frame.index + self.cfg.selection.reach))
        for p in past:
            if p.T_WC is not None:
                views[p.index] = ReferenceView(p.rgb, p.depth, p.T_WC, p.moving())
                cands.append(Candidate(p.index, p.T_WC, p.features.desc if p.features is not None else None))
        future: dict[int, tuple[Frame, np.ndarray]] = {}
        if both and later is None and inputs.features is not None:
            future = self._future_poses(frame, hole, inputs.features, T_target, ctx)
            cands += [Candidate(j, T_WC, self.ahead[j][1].desc) for j, (_, T_WC) in future.items()]
        sel = select_references(Candidate(frame.index, T_target, desc), cands, self.cfg.selection, both)
        self.relaxed += int(sel.relaxed)
        self.far_refs += len(sel.far)
        for j in sel.indices:
            if j in future:  # moving pixels only for the chosen: the test costs a full-image warp
                f, T_WC = future[j]
                T_ft = np.linalg.inv(T_WC) @ T_target
                dyn = moving_pixels(f.depth, T_ft, frame.depth, hole, self.camera.K, self.cfg.lookahead)
                views[j] = ReferenceView(f.rgb, f.depth, T_WC, dyn)
                self.future_refs += 1
        if later is not None:
            self.future_refs += sum(i > frame.index for i in sel.indices)
        margin = self.cfg.reference_margin_px
        refs = [replace(views[i], dynamic=_widen(views[i].dynamic, margin)) for i in sel.indices]
        out = restore_frame(frame.rgb, frame.depth, hole, T_target, refs, self.camera.K, self.cfg.restoration)
        inputs.restored_rgb, inputs.restored_depth = out.rgb, out.depth
        inputs.deferred = None
        self.restored_frames += 1
        self.restored_for[why] += 1
        self.poses_refined += out.poses_refined
        self.references_used += len(refs)
        inputs.info.update(references=len(refs),
                           hole_seen_fraction=float(out.seen_by_reference.sum() / max(hole.sum(), 1)))
        if self.cfg.restored_features:
            extra = self._restored_features(out, hole, inputs.features)
            inputs.extra_features = extra
            self.extra += len(extra)
            inputs.info["restored_features"] = len(extra)
        inputs.previews = {"rgb": frame.rgb, "mask": _overlay(frame.rgb, hole), "restored": out.rgb}

    def _future_poses(self, frame: Frame, hole: np.ndarray, own: Features, T_pred: np.ndarray,
                      ctx: StageContext) -> dict[int, tuple[Frame, np.ndarray]]:
        """Candidate future frames (every `candidate_stride`-th of the next `window`) with their T_WC (4,4),
        estimated by PnP against the target at its predicted pose; frames PnP cannot place are left out."""
        seq = ctx.sequence
        if seq is None:
            raise ValueError("both-sided restoration reads frames ahead and needs the run's sequence")
        sel = self.cfg.selection
        last = min(frame.index + sel.window, len(seq) - 1)
        wanted = range(frame.index + sel.candidate_stride, last + 1, sel.candidate_stride)
        # kept for the whole window, not just this frame's candidates: the next frame's (other parity) need them
        self.ahead = {j: v for j, v in self.ahead.items() if frame.index < j <= last}
        out: dict[int, tuple[Frame, np.ndarray]] = {}
        for j in wanted:
            if j not in self.ahead:
                f = seq[j]
                gray = cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY)
                self.ahead[j] = (f, self.extractor.extract(gray, f.depth))
            f, feats = self.ahead[j]
            est = relative_pose_pnp(own, ~hole, feats, self.camera.K, self.cfg.lookahead)
            if est is not None:
                out[j] = (f, T_pred @ np.linalg.inv(est[0]))
        return out

    def _restored_features(self, out: Restoration, hole: np.ndarray, own: Features | None) -> Features:
        region = cv2.dilate(hole.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        gray = cv2.cvtColor(out.rgb, cv2.COLOR_RGB2GRAY)
        feats = self.extractor.extract(gray, out.depth, ~region)
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
        """Run-level figures (the evaluation against truth adds its "truth" entry: `run.truth_observer`)."""
        return {"references": self.cfg.references, "restored_frames": self.restored_frames,
                "deferred_future": self.cfg.deferred_future if self.cfg.references == "both-sided" else None,
                "restored_for": dict(sorted(self.restored_for.items())),
                "not_restored": self.deferred - self.restored_for["keyframe"] - self.restored_for["preview"],
                "future_references": self.future_refs, "far_references": self.far_refs,
                "restored_features": self.extra,
                "references_used": self.references_used, "reference_poses_refined": self.poses_refined,
                "relaxed_reference_choices": self.relaxed}


def _overlay(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    out = rgb.copy()
    out[mask] = (0.5 * out[mask] + 0.5 * np.array([255, 40, 40])).astype(np.uint8)
    return out


def _widen(mask: np.ndarray, px: int) -> np.ndarray:
    """`mask` (H, W) bool dilated by `px` pixels, a square (one separable pass). Not culling's
    `dilate_disc`: inpainting may not import its floor, and a disc of radius 8 kept more of the fringe
    (docs/results/settings.md#restoration-reference_margin_px)."""
    if px <= 0 or not mask.any():
        return mask
    return cv2.dilate(mask.astype(np.uint8), np.ones((2 * px + 1, 2 * px + 1), np.uint8)) > 0
