"""The dynamic stages' outputs scored against the sequence's ground truth (`truth/`), outside the stages.

The run feeds the observer each frame's stage outputs after the stages ran, and a deferred restoration's when it
completes. Culling is scored on the frames it compared with a past one (`FrameInputs.culled` set): its dynamic
mask (IoU) and its keypoints (precision, recall and, with segmentation, the misses' split; `truth.TruthScores`);
restoration on every restored frame: PSNR and median depth error over the filled hole; per true mover class
(`truth_classes`), the share of its pixels segmentation marked potentially dynamic and culling judged moving. The
summaries are the "truth" entries of the stages' metrics.json sections.
"""
from __future__ import annotations

import numpy as np

from worker.slam.run.truth_classes import ClassRecall, TruthClasses
from worker.slam.stages import FrameInputs
from worker.slam.truth import Truth, TruthScores, restoration_psnr


class TruthObserver:
    """Call `frame(index, inputs)` for every frame after its stages ran, `restored(index, inputs, hole)` for a
    deferred restoration when it completes; `summaries()` at the end. Used on the pipeline thread only."""

    def __init__(self, truth: Truth) -> None:
        self.truth = truth
        self.scores = TruthScores(truth)
        self.seen_frames = 0
        self.psnr: list[float] = []
        """dB per restored frame, identical pixels as 100 dB (so the mean stays finite)."""
        self.depth_err: list[float] = []
        """Median absolute depth error (m) per restored frame with valid restored and true depth in the hole."""
        self.classes = TruthClasses(truth)
        self.marked = ClassRecall()
        """Per true mover class: its pixels segmentation marked potentially dynamic (every frame it ran on)."""
        self.culled = ClassRecall()
        """Per true mover class: its pixels in culling's dynamic mask (the frames culling compared)."""

    def frame(self, index: int, inputs: FrameInputs) -> None:
        """Score frame `index`'s outputs: culling's when it compared, restoration's when it restored in `process`."""
        self.seen_frames += 1
        if index >= len(self.truth):
            return
        extracted, culled, moving = inputs.extracted, inputs.culled, inputs.dynamic_mask
        compared = culled is not None and extracted is not None and moving is not None
        if culled is not None and extracted is not None and moving is not None:
            self.scores.add_mask(index, moving)
            self.scores.add_features(index, extracted.uv[culled], extracted.uv[~culled],
                                     marked=inputs.potentially_dynamic)
        if inputs.potentially_dynamic is not None or compared:
            masks = self.classes.masks(index)
            if inputs.potentially_dynamic is not None:
                self.marked.add(masks, inputs.potentially_dynamic)
            if compared and moving is not None:
                self.culled.add(masks, moving)
        self.restored(index, inputs, inputs.dynamic_mask)

    def restored(self, index: int, inputs: FrameInputs, hole: np.ndarray | None) -> None:
        """Score frame `index`'s restored images (if any) over `hole` (H, W) bool, the dynamic mask (None: none)."""
        rgb, depth = inputs.restored_rgb, inputs.restored_depth
        if rgb is None or depth is None or index >= len(self.truth):
            return
        hole = hole if hole is not None else np.zeros(depth.shape, bool)
        self.psnr.append(min(restoration_psnr(rgb, self.truth.background_rgb(index), hole), 100.0))
        bg = self.truth.background_depth(index)
        ok = hole & (depth > 0) & (bg > 0)
        if ok.any():
            self.depth_err.append(float(np.median(np.abs(depth[ok] - bg[ok]))))

    def summaries(self, stages: list[str]) -> dict[str, dict]:
        """The "truth" entry of each of `stages` (the run's stage names) that has one, by stage name: segmentation's
        (`recall_by_class`) once it marked a frame, culling's (with `mask_recall_by_class`) once it saw a frame,
        restoration's once it restored one."""
        out: dict[str, dict] = {}
        if "segmentation" in stages and self.marked.frames:
            out["segmentation"] = {"frames_scored": self.marked.frames, "recall_by_class": self.marked.summary()}
        if "culling" in stages and self.seen_frames:
            out["culling"] = {k: v for k, v in self.scores.summary().items() if k != "restoration_psnr"}
            out["culling"]["mask_recall_by_class"] = self.culled.summary()
        if "restoration" in stages and self.psnr:
            # over the restored frames only: on demand, those are the keyframes and previews (`restored_for`)
            out["restoration"] = {"frames_scored": len(self.psnr), "restoration_psnr": float(np.mean(self.psnr)),
                                  "restoration_depth_median_m": float(np.median(self.depth_err)) if self.depth_err
                                  else None}
        return out
