"""How much of the frames each class covered over a run: the segmentation stage's figures in metrics.json."""
from __future__ import annotations

import numpy as np

from formats.class_palette import legend


def pixel_counts(labels: np.ndarray, classes: int) -> np.ndarray:
    """(classes,) int64 pixel counts of `labels` (H, W) uint8 indices (a label past `classes` is dropped)."""
    return np.bincount(labels.ravel(), minlength=classes)[:classes]


class ClassShares:
    """Per-frame shares of the image each class covers, averaged over the frames `add`ed."""

    def __init__(self, classes: tuple[str, ...], dynamic: tuple[str, ...]) -> None:
        self.classes, self.dynamic = classes, dynamic
        self.total = np.zeros(len(classes), np.float64)
        """Sum over frames of each class's share of its frame."""
        self.frames = 0

    def add(self, counts: np.ndarray) -> None:
        """One frame's `pixel_counts` (over `classes`)."""
        n = counts.sum()
        if n:
            self.total += counts / n
            self.frames += 1

    def summary(self) -> dict:
        """`class_share`: mean share of the frame per potentially dynamic class that covered any pixel, largest
        first; `other_class_share`: the same for the other non-background classes (seen, not masked);
        `legend`: every class seen, its palette colour and whether it counts as dynamic (`formats.class_palette`)."""
        mean = self.total / max(self.frames, 1)
        order = [i for i in np.argsort(-mean, kind="stable") if mean[i] > 0 and self.classes[i] != "background"]
        dyn = set(self.dynamic)
        share = {self.classes[i]: round(float(mean[i]), 5) for i in order if self.classes[i] in dyn}
        other = {self.classes[i]: round(float(mean[i]), 5) for i in order if self.classes[i] not in dyn}
        return {"class_share": share, "other_class_share": other,
                "legend": legend([self.classes[i] for i in order], self.dynamic)}
