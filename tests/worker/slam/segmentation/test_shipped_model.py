"""The shipped checkpoint on the real TUM walking_xyz frame (two people, two chairs)."""
from __future__ import annotations

from pathlib import Path
from typing import cast

import cv2
import numpy as np
import pytest

from worker.slam.io.images import read_rgb
from worker.slam.segmentation import SegmenterConfig, make_segmenter
from worker.slam.segmentation.evaluate import tum_person_mask
from worker.slam.segmentation.guided import CHOSEN_RADIUS


@pytest.mark.realdata
def test_shipped_checkpoint_runs_on_real_frame(shared: Path) -> None:
    folder = shared / "data" / "tum_frames" / "fr3_walking_xyz"
    rgb_path = next(folder.glob("rgb_*.png"), None)
    if rgb_path is None:
        pytest.skip(f"walking_xyz frame missing in {folder}")
    res = make_segmenter(SegmenterConfig(device="cpu", with_probs=True)).segment(read_rgb(rgb_path))
    assert res.labels.shape == (480, 640) and res.probs is not None and np.isfinite(res.probs).all()


@pytest.mark.realdata
def test_shipped_msnet_person_iou_on_walking_xyz(shared: Path) -> None:
    """A regression floor just below the measured 0.790 (2026-12-05, the `cpu-real-mnv2` checkpoint; the one
    before it had 0.640, the `cpu-tum` one 0.697; the issue's target is 0.75, see weights/MODEL_CARD.md). A
    checkpoint that does clearly worse than the shipped one fails here. The optional guided upsampling (0.779
    with this checkpoint) beat bilinear with the `cpu-tum` checkpoint and loses since: a floor keeps it honest."""
    folder = shared / "data" / "tum_frames" / "fr3_walking_xyz"
    rgb_path = next(folder.glob("rgb_*.png"), None)
    mask_path = next(folder.glob("person_mask_*.png"), None)
    if rgb_path is None or mask_path is None:
        pytest.skip(f"walking_xyz frame or mask missing in {folder}")
    rgb = read_rgb(rgb_path)
    gt = tum_person_mask(cast(np.ndarray, cv2.imread(str(mask_path), cv2.IMREAD_UNCHANGED)))  # None: unreadable
    ious = {}
    for radius in (0, CHOSEN_RADIUS):
        res = make_segmenter(SegmenterConfig(device="cpu", guided_radius=radius)).segment(rgb)
        pred = res.class_mask("person")
        ious[radius] = np.logical_and(pred, gt).sum() / np.logical_or(pred, gt).sum()
        assert res.dynamic_mask()[pred].all()
    assert ious[0] >= 0.77, f"person IoU {ious[0]:.3f} fell below the shipped checkpoint's 0.790"
    assert ious[CHOSEN_RADIUS] >= 0.75, ious
