"""The true movers' classes, and how much of each class a run's masks covered (the evaluation against truth).

A sequence from `vtdslam augment --movers ...` names the COCO class of every pasted pixel (`truth/classes`, COCO-80
id + 1, named by `truth.json`'s `generator.classes_mask`); any other sequence with truth names each moving object's
class in `truth.json`'s `objects` (`{"id", "class"}`: people-only augmentation and `vtdslam synth` say `person`).
"""
from __future__ import annotations

import numpy as np

from formats.class_names import COCO_CLASSES
from worker.slam.errors import SequenceFormatError
from worker.slam.truth import Truth


class TruthClasses:
    """Reads, per frame, which class each truly moving pixel belongs to."""

    def __init__(self, truth: Truth) -> None:
        self.truth = truth
        self.template: str | None = truth.layout.generator.get("classes_mask")
        self.by_id = {int(o["id"]): str(o.get("class", "mover")) for o in truth.layout.objects if "id" in o}

    def masks(self, index: int) -> dict[str, np.ndarray]:
        """Class name -> (H, W) bool: the moving pixels of that class in frame `index` (only classes present)."""
        ids = self.truth.ids(index)
        moving = ids > 0
        if self.template is None:
            names, layer = self.by_id, ids
        else:
            layer = self._classes(index)
            if layer.shape != ids.shape:
                raise SequenceFormatError("truth classes image and mask differ in size", path=self.truth.root)
            names = {c + 1: name for c, name in enumerate(COCO_CLASSES)}
        out: dict[str, np.ndarray] = {}
        for v in np.unique(layer[moving]):
            name = names.get(int(v), "mover" if self.template is None else "unknown")
            hit = moving & (layer == v)
            out[name] = out[name] | hit if name in out else hit  # objects of one class pool their pixels
        return out

    def _classes(self, index: int) -> np.ndarray:
        import cv2

        assert self.template is not None
        path = self.truth.root / self.template.format(index=index)
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) if path.is_file() else None
        if img is None or img.ndim != 2 or img.dtype != np.uint8:
            raise SequenceFormatError("truth classes image missing or not single-channel 8-bit", path=path)
        return img


class ClassRecall:
    """Pixels of each true mover class, and how many of them a mask covered, pooled over frames."""

    def __init__(self) -> None:
        self.counts: dict[str, list[int]] = {}
        """class name -> [true moving pixels, of them covered]."""
        self.frames = 0

    def add(self, masks: dict[str, np.ndarray], covered: np.ndarray) -> None:
        """One frame's `TruthClasses.masks` and a (H, W) bool mask (segmentation's or culling's)."""
        self.frames += 1
        for name, m in masks.items():
            pair = self.counts.setdefault(name, [0, 0])
            pair[0] += int(np.count_nonzero(m))
            pair[1] += int(np.count_nonzero(m & covered))

    def summary(self) -> dict[str, dict[str, float | int]]:
        """class name -> {"recall": covered / true pixels, "pixels": true pixels}, by class name."""
        return {k: {"recall": round(c / n, 4), "pixels": n} for k, (n, c) in sorted(self.counts.items()) if n}
