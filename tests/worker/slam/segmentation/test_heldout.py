"""Held-out person sets: mask folders, the seeded hash split, teacher-made references and pooled scores."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from worker.slam.segmentation.base import SegmentationResult
from worker.slam.segmentation.heldout import EvalImage, HeldOutSet, score_set
from worker.slam.segmentation.reference_masks import IGNORE, drop_small, with_ignore_band
from worker.slam.segmentation.train.datasets import (
    hash_split,
    load_mask_folder,
    object_masks,
    semantic_mask,
)

CLASSES = ("background", "person", "chair")


def _mask_folder(root: Path, n: int) -> Path:
    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    for i in range(n):
        cv2.imwrite(str(root / "images" / f"{i:04d}.jpg"), np.full((40, 30, 3), 100, np.uint8))
        mask = np.zeros((40, 30), np.uint8)
        mask[10:30, 5:20] = 255
        cv2.imwrite(str(root / "masks" / f"{i:04d}.png"), mask)
    return root


def test_mask_folder_items_give_semantic_masks_and_one_object(tmp_path: Path) -> None:
    items = load_mask_folder(_mask_folder(tmp_path / "ccp", 2), "person")
    assert len(items) == 2 and items[0].size == (40, 30) and items[0].partial
    sem = semantic_mask(items[0], CLASSES)
    assert sem[20, 10] == 1 and sem[5, 5] == 0 and (sem == 1).sum() == 20 * 15
    (mask, label), = object_masks(items[0], CLASSES)
    assert label == 1 and mask.sum() == 20 * 15


def test_hash_split_is_fixed_by_file_name_alone(tmp_path: Path) -> None:
    items = load_mask_folder(_mask_folder(tmp_path / "a", 200), "person")
    train, val, test = hash_split(items, 0.25, 0.1)
    names = [{i.image.name for i in s} for s in (train, val, test)]
    assert len(train) + len(val) + len(test) == 200
    assert not (names[0] & names[1]) and not (names[0] & names[2]) and not (names[1] & names[2])
    assert 30 <= len(test) <= 70 and 8 <= len(val) <= 32
    # dropping half the files moves none of the others across splits
    _, val2, test2 = hash_split(items[::2], 0.25, 0.1)
    assert {i.image.name for i in test2} == names[2] & {i.image.name for i in items[::2]}
    assert {i.image.name for i in val2} == names[1] & {i.image.name for i in items[::2]}
    # another seed is another split
    assert {i.image.name for i in hash_split(items, 0.25, 0.1, seed=1)[2]} != names[2]


def test_reference_ignore_band_and_small_blobs() -> None:
    person = np.zeros((40, 40), bool)
    person[10:30, 10:30] = True
    person[2:4, 35:37] = True  # a 4-pixel speck
    clean = drop_small(person, 50)
    assert clean[20, 20] and not clean[2, 35]
    ref = with_ignore_band(clean, 2)
    assert ref[20, 20] == 1 and ref[0, 0] == 0 and ref[10, 20] == IGNORE and ref[8, 20] == IGNORE
    assert ref[7, 20] == 0 and ref[12, 20] == 1


class _Fixed:
    """A segmenter that marks a fixed square as person."""

    classes: tuple[str, ...] = ("background", "person")
    dynamic_classes: tuple[str, ...] = ("person",)

    def segment(self, rgb: np.ndarray) -> SegmentationResult:
        labels = np.zeros(rgb.shape[:2], np.uint8)
        labels[0:10, 0:10] = 1
        return SegmentationResult(labels, self.classes, self.dynamic_classes)


def test_pooled_scores_leave_ignored_pixels_out(tmp_path: Path) -> None:
    img = tmp_path / "x.png"
    cv2.imwrite(str(img), np.zeros((20, 20, 3), np.uint8))
    truth = np.zeros((20, 20), np.uint8)
    truth[0:10, 5:15] = 1  # 50 of the 100 predicted pixels are right; truth has 100
    truth[0:10, 0:2] = IGNORE  # 20 predicted pixels are ignored
    s = score_set(_Fixed(), HeldOutSet("t", (EvalImage(img, lambda: truth),), ""))
    assert s.precision == pytest.approx(50 / 80) and s.recall == pytest.approx(50 / 100)
    assert s.iou == pytest.approx(50 / (80 + 100 - 50)) and s.marked == pytest.approx(80 / 380)
    empty = score_set(_Fixed(), HeldOutSet("e", (EvalImage(img, None),) * 2, ""))
    assert empty.iou is None and empty.recall is None and empty.marked == pytest.approx(100 / 400)


@pytest.mark.realdata
def test_ccp_test_split_is_a_fifth_and_never_trained_on(shared: Path) -> None:
    from worker.slam.segmentation.train.config import load_train_config
    from worker.slam.segmentation.train.data import split_labelled, split_mask_dirs

    cfg = load_train_config("cpu-real", shared_dir=str(shared))
    train, val, test = split_mask_dirs(cfg)
    assert len(train) + len(val) + len(test) == 600
    assert len(test) >= 120 and len(val) >= 40
    all_train, all_val, all_test = split_labelled(cfg)
    names = [{str(i.image) for i in s} for s in (all_train, all_val, all_test)]
    assert {str(i.image) for i in test} <= names[2] and {str(i.image) for i in val} <= names[1]
    assert not (names[0] & names[2]) and not (names[0] & names[1]) and not (names[1] & names[2])
    assert len(all_test) == len(test) + 26  # plus COCO128's held-out split
