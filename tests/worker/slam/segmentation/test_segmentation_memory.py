"""`segmentation.memory_frames`: a frame's network mask also marks what the last few frames' masks marked."""
from __future__ import annotations

from types import SimpleNamespace
from typing import cast

import numpy as np

from worker.slam.camera import Camera
from worker.slam.io.sequence import Frame
from worker.slam.presets import get_preset
from worker.slam.segmentation.base import SegmentationResult
from worker.slam.segmentation.stage import SegmentationStage
from worker.slam.stages import FrameInputs, StageContext


class _Masks:
    """A segmenter that marks one given column per frame (frame i: column i)."""

    classes: tuple[str, ...] = ("background", "person")
    dynamic_classes: tuple[str, ...] = ("person",)

    def segment(self, rgb: np.ndarray) -> SegmentationResult:
        labels = np.zeros(rgb.shape[:2], np.uint8)
        labels[:, int(rgb[0, 0, 0])] = 1
        return SegmentationResult(labels, self.classes, self.dynamic_classes)


def _marked_columns(memory_frames: int, frames: int = 5) -> list[list[int]]:
    cfg = get_preset("no-restoration", {"segmentation": {"memory_frames": memory_frames}})
    stage = SegmentationStage(cfg, Camera(fx=500, fy=500, cx=4, cy=3, width=8, height=6))
    stage.segmenter = _Masks()
    out = []
    for i in range(frames):
        rgb = np.full((6, 8, 3), i, np.uint8)
        frame = Frame(i, i / 30, rgb, np.ones((6, 8), np.float32))
        got = stage.process(frame, FrameInputs(), cast(StageContext, SimpleNamespace())).potentially_dynamic
        assert got is not None
        out.append(np.flatnonzero(got.any(0)).tolist())
    return out


def test_without_memory_each_frame_keeps_its_own_mask():
    assert _marked_columns(0) == [[0], [1], [2], [3], [4]]


def test_memory_adds_the_previous_frames_masks_and_forgets_older_ones():
    assert _marked_columns(1) == [[0], [0, 1], [1, 2], [2, 3], [3, 4]]
    assert _marked_columns(2) == [[0], [0, 1], [0, 1, 2], [1, 2, 3], [2, 3, 4]]
