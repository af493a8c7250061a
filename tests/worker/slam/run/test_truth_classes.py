"""Scores by true mover class: the share of each class's moving pixels segmentation marked and culling culled."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from tests.worker.slam.test_truth import _write_tiny
from worker.slam.errors import SequenceFormatError
from worker.slam.run.truth_classes import ClassRecall, TruthClasses
from worker.slam.run.truth_observer import TruthObserver
from worker.slam.stages import FrameInputs
from worker.slam.truth import Truth, load_truth

DOG, CAR = 16, 2  # COCO-80 ids; truth/classes holds id + 1


def _with_classes(root, frames) -> None:
    """Give the tiny sequence the augmenter's per-pixel classes: the mover's left half a dog, its right half a car."""
    meta = json.loads((root / "truth" / "truth.json").read_text())
    meta["generator"]["classes_mask"] = "classes/{index:06d}.png"
    (root / "truth" / "truth.json").write_text(json.dumps(meta))
    (root / "truth" / "classes").mkdir()
    for i, (_, _, ids, _, _) in enumerate(frames):
        cls = np.zeros(ids.shape, np.uint8)
        ys, xs = np.nonzero(ids)
        mid = (xs.min() + xs.max() + 1) // 2
        cls[(ids > 0) & (np.arange(ids.shape[1]) < mid)] = DOG + 1
        cls[(ids > 0) & (np.arange(ids.shape[1]) >= mid)] = CAR + 1
        cls[0, 0] = 57  # a static pasted chair's pixel: not a mover
        cv2.imwrite(str(root / "truth" / "classes" / f"{i:06d}.png"), cls)


def test_classes_from_truth_objects_without_a_classes_image(tmp_path) -> None:
    frames = _write_tiny(tmp_path)
    masks = TruthClasses(_truth(tmp_path)).masks(0)
    assert set(masks) == {"person"} and (masks["person"] == (frames[0][2] > 0)).all()


def test_classes_from_the_augmenters_classes_image(tmp_path) -> None:
    frames = _write_tiny(tmp_path)
    _with_classes(tmp_path, frames)
    masks = TruthClasses(_truth(tmp_path)).masks(1)
    moving = frames[1][2] > 0
    assert set(masks) == {"dog", "car"}
    assert (masks["dog"] | masks["car"] == moving).all() and not (masks["dog"] & masks["car"]).any()
    (tmp_path / "truth" / "classes" / "000002.png").unlink()
    with pytest.raises(SequenceFormatError, match="classes image"):
        TruthClasses(_truth(tmp_path)).masks(2)


def test_recall_pools_pixels_over_frames() -> None:
    rec = ClassRecall()
    a = np.zeros((4, 4), bool)
    a[0] = True
    rec.add({"dog": a}, a & (np.arange(4) < 1))  # 1 of 4
    rec.add({"dog": a, "car": ~a}, a)  # 4 of 4; car 0 of 12
    assert rec.summary() == {"car": {"recall": 0.0, "pixels": 12}, "dog": {"recall": 0.625, "pixels": 8}}


def test_observer_scores_marked_and_culled_pixels_per_class(tmp_path) -> None:
    frames = _write_tiny(tmp_path)
    _with_classes(tmp_path, frames)
    obs = TruthObserver(_truth(tmp_path))
    for i, (_, _, ids, _, _) in enumerate(frames):
        dog = TruthClasses(_truth(tmp_path)).masks(i)["dog"]
        inputs = FrameInputs(potentially_dynamic=ids > 0)  # segmentation marked both movers
        if i > 0:  # culling compared: it judged only the dog moving
            inputs.dynamic_mask, inputs.culled = dog, np.zeros(0, bool)
            inputs.extracted = _no_features()
        obs.frame(i, inputs)
    s = obs.summaries(["segmentation", "culling"])
    assert s["segmentation"]["frames_scored"] == 3
    assert {k: v["recall"] for k, v in s["segmentation"]["recall_by_class"].items()} == {"car": 1.0, "dog": 1.0}
    assert {k: v["recall"] for k, v in s["culling"]["mask_recall_by_class"].items()} == {"car": 0.0, "dog": 1.0}


def _no_features():
    from worker.slam.features.types import Features

    return Features(np.zeros((0, 2), np.float32), np.zeros(0, np.int32), np.zeros(0, np.float32),
                    np.zeros((0, 32), np.uint8), np.zeros(0, np.float32))


def _truth(root) -> Truth:
    truth = load_truth(root)
    assert truth is not None
    return truth
