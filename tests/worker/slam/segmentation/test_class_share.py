"""The segmentation stage's class figures: each class's mean share of the frames, its classes for the previews."""
from __future__ import annotations

from types import SimpleNamespace
from typing import cast

import numpy as np
import pytest

from worker.slam.camera import Camera
from worker.slam.io.sequence import Frame
from worker.slam.presets import get_preset
from worker.slam.segmentation.base import SegmentationResult
from worker.slam.segmentation.class_share import ClassShares, pixel_counts
from worker.slam.segmentation.stage import SegmentationStage
from worker.slam.stages import FrameInputs, StageContext

CLASSES = ("background", "person", "car", "sofa")


class _Chosen:
    """A segmenter returning a chosen label map per frame (frame i: the i-th of `maps`)."""

    classes: tuple[str, ...] = CLASSES
    dynamic_classes: tuple[str, ...] = ("person", "car")

    def __init__(self, maps: list[np.ndarray]) -> None:
        self.maps = maps

    def segment(self, rgb: np.ndarray) -> SegmentationResult:
        return SegmentationResult(self.maps[int(rgb[0, 0, 0])], self.classes, self.dynamic_classes)


def _maps() -> list[np.ndarray]:
    a = np.zeros((10, 10), np.uint8)
    a[:3] = 1  # person 30 %
    a[9, :5] = 3  # sofa 5 %
    b = np.zeros((10, 10), np.uint8)
    b[:1] = 1  # person 10 %
    b[5:7] = 2  # car 20 %
    return [a, b]


def test_shares_average_over_frames_and_split_dynamic_from_other() -> None:
    shares = ClassShares(CLASSES, ("person", "car"))
    for m in _maps():
        shares.add(pixel_counts(m, len(CLASSES)))
    s = shares.summary()
    assert s["class_share"] == {"person": pytest.approx(0.2), "car": pytest.approx(0.1)}
    assert list(s["class_share"]) == ["person", "car"]  # largest first
    assert s["other_class_share"] == {"sofa": pytest.approx(0.025)}
    assert [e["name"] for e in s["legend"]] == ["person", "car", "sofa"]
    assert s["legend"][0] == {"name": "person", "colour": "#c08080", "dynamic": True}
    assert ClassShares(CLASSES, ()).summary()["class_share"] == {}  # no frame: nothing seen


def test_stage_hands_on_the_classes_and_sums_up_the_run() -> None:
    cfg = get_preset("no-restoration", {"segmentation": {"memory_frames": 0}})
    stage = SegmentationStage(cfg, Camera(fx=500, fy=500, cx=5, cy=5, width=10, height=10))
    stage.segmenter = _Chosen(_maps())
    ctx = cast(StageContext, SimpleNamespace())
    for i in range(2):
        frame = Frame(i, i / 30, np.full((10, 10, 3), i, np.uint8), np.ones((10, 10), np.float32))
        inputs = FrameInputs()
        inputs.prepared["segmentation"] = stage.prepare(frame)  # as the pipeline's look-ahead thread gives it
        out = stage.process(frame, inputs, ctx)
        assert out.class_labels is not None and out.class_labels.classes == CLASSES
        assert (out.class_labels.labels == _maps()[i]).all()
        assert out.potentially_dynamic is not None
        assert (out.potentially_dynamic == np.isin(_maps()[i], [1, 2])).all()
    s = stage.summary()
    assert s["source"] == "network" and s["frames"] == 2 and s["dynamic_classes"] == ["person", "car"]
    assert s["class_share"] == {"person": pytest.approx(0.2), "car": pytest.approx(0.1)}
