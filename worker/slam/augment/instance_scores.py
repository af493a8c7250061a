"""Culling scored per pasted instance: did it remove the movers' keypoints and keep the static instances'?

An augmented sequence with movers other than people or with static instances (`generator.py`) has, beside its
truth masks (moving instances), per-frame images of every pasted pixel's COCO class and of the static
instances. `InstanceScoreStage` is a bench-only stage appended after the pipeline's own: each frame culling
compared (`FrameInputs.culled` set), it counts the extracted keypoints removed and kept on moving instances
(by class), on static instances, and on the source scene (the rest), so that "culling keeps a parked chair's
features" is a number next to the moving recall.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from worker.slam.augment.movers import COCO80
from worker.slam.errors import SequenceFormatError
from worker.slam.io.sequence import Frame
from worker.slam.stages import FrameInputs, StageContext
from worker.slam.truth import Truth, load_truth

INTERIOR_PX = 8


@dataclass(frozen=True)
class InstanceLayers:
    """One frame's instance truth: `moving` uint8 (H, W) moving ids (the truth mask), `static` uint8 (H, W)
    static instance ids, `classes` uint8 (H, W) COCO-80 id + 1 of every pasted pixel (0 = source scene)."""

    moving: np.ndarray
    static: np.ndarray
    classes: np.ndarray


class InstanceTruth:
    """Reads the class and static-instance images an augmented sequence's `truth.json` names."""

    def __init__(self, truth: Truth) -> None:
        gen = truth.layout.generator
        if "classes_mask" not in gen or "static_mask" not in gen:
            raise SequenceFormatError("no per-instance truth (augment with --movers other than person, or --static)",
                                      path=truth.root)
        self.truth = truth
        self.templates = {"classes": gen["classes_mask"], "static": gen["static_mask"]}

    @classmethod
    def of(cls, seq_root: Path | str) -> InstanceTruth | None:
        """The instance truth of a sequence folder, None when it has no truth or no per-instance images."""
        truth = load_truth(seq_root)
        if truth is None or "classes_mask" not in truth.layout.generator:
            return None
        return cls(truth)

    def _read(self, kind: str, index: int) -> np.ndarray:
        path = self.truth.root / self.templates[kind].format(index=index)
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) if path.is_file() else None
        if img is None or img.ndim != 2 or img.dtype != np.uint8:
            raise SequenceFormatError(f"{kind} truth image missing or not single-channel 8-bit", path=path)
        return img

    def __getitem__(self, index: int) -> InstanceLayers:
        return InstanceLayers(self.truth.ids(index), self._read("static", index), self._read("classes", index))


@dataclass
class InstanceCounts:
    """Keypoints culling removed / kept, pooled over the frames it compared."""

    moving: dict[str, list[int]] = field(default_factory=dict)
    """class name -> [removed, kept] on moving instances."""
    static: list[int] = field(default_factory=lambda: [0, 0])
    """[removed, kept] on static instances."""
    static_interior: list[int] = field(default_factory=lambda: [0, 0])
    """[removed, kept] on static instances at least `INTERIOR_PX` inside their silhouette (a corner on the
    silhouette mixes the instance with the scene behind it, which parallax moves)."""
    scene: list[int] = field(default_factory=lambda: [0, 0])
    """[removed, kept] on the source scene, more than `border_px` from any pasted pixel."""

    def add(self, layers: InstanceLayers, uv: np.ndarray, culled: np.ndarray, border_px: int) -> None:
        """Count keypoints `uv` (N, 2) (x, y) pixels, `culled` bool (N,) removed, against one frame's layers."""
        h, w = layers.moving.shape
        x = np.clip(np.rint(uv[:, 0]).astype(int), 0, w - 1)
        y = np.clip(np.rint(uv[:, 1]).astype(int), 0, h - 1)
        cls, moving, static = layers.classes[y, x], layers.moving[y, x] > 0, layers.static[y, x] > 0
        pasted = cv2.dilate((layers.classes > 0).astype(np.uint8), np.ones((2 * border_px + 1,) * 2, np.uint8))
        scene = pasted[y, x] == 0
        k = 2 * INTERIOR_PX + 1
        interior = static & (cv2.erode((layers.static > 0).astype(np.uint8), np.ones((k, k), np.uint8))[y, x] > 0)
        for c in np.unique(cls[moving]):
            on = moving & (cls == c)
            pair = self.moving.setdefault(COCO80[int(c) - 1], [0, 0])
            pair[0] += int((on & culled).sum())
            pair[1] += int((on & ~culled).sum())
        for pair, on in ((self.static, static), (self.static_interior, interior), (self.scene, scene)):
            pair[0] += int((on & culled).sum())
            pair[1] += int((on & ~culled).sum())

    def summary(self) -> dict:
        """Shares removed (None without keypoints) and the counts behind them."""
        def share(pair: list[int]) -> float | None:
            return pair[0] / sum(pair) if sum(pair) else None

        moved = [sum(p[0] for p in self.moving.values()), sum(p[1] for p in self.moving.values())]
        return {"moving_removed": share(moved), "static_removed": share(self.static),
                "static_interior_removed": share(self.static_interior), "scene_removed": share(self.scene),
                "moving_by_class": {k: {"removed": share(v), "keypoints": sum(v)}
                                    for k, v in sorted(self.moving.items())},
                "keypoints": {"moving": sum(moved), "static": sum(self.static),
                              "static_interior": sum(self.static_interior), "scene": sum(self.scene)}}


class InstanceScoreStage:
    """A stage that changes nothing: appended last, it scores culling's decisions per instance (see module)."""

    name = "instance_truth"

    def __init__(self, truth: InstanceTruth, border_px: int = 3) -> None:
        self.truth, self.border_px = truth, border_px
        self.counts = InstanceCounts()
        self.frames = 0

    def process(self, frame: Frame, inputs: FrameInputs, ctx: StageContext) -> FrameInputs:
        ex, culled = inputs.extracted, inputs.culled
        if ex is not None and culled is not None and frame.index < len(self.truth.truth):
            self.counts.add(self.truth[frame.index], np.asarray(ex.uv), np.asarray(culled, bool), self.border_px)
            self.frames += 1
        return inputs

    def summary(self) -> dict:
        return {"frames": self.frames, **self.counts.summary()}
