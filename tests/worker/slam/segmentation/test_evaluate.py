"""Metrics on hand-made label maps."""
from __future__ import annotations

import numpy as np

from worker.slam.segmentation.evaluate import agreement, align_labels, confusion, metrics_from_confusion


def test_iou_and_pixel_accuracy() -> None:
    gt = np.array([[0, 0, 1, 1], [0, 0, 1, 255]], np.uint8)
    pred = np.array([[0, 1, 1, 1], [0, 0, 0, 2]], np.uint8)
    m = metrics_from_confusion(confusion(pred, gt, 3), ("background", "person", "chair"), images=1)
    assert m.iou["background"] == 3 / 5 and m.iou["person"] == 2 / 4
    assert m.pixel_acc["person"] == 2 / 3 and m.pixel_acc["chair"] is None and m.iou["chair"] is None
    assert np.isclose(m.miou, (0.6 + 0.5) / 2) and np.isclose(m.mpa, (3 / 4 + 2 / 3) / 2)


def test_align_and_agreement() -> None:
    labels = np.array([[0, 1]], np.uint8)
    assert align_labels(labels, ("background", "person"), ("background", "chair", "person")).tolist() == [[0, 2]]
    assert agreement(np.array([1, 1, 0]), np.array([1, 0, 0]), 1) == 0.5
