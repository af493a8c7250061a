"""YOLO-seg and COCO JSON parsing, rasterisation and the held-out split."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from worker.slam.errors import SequenceFormatError
from worker.slam.segmentation.train.datasets import load_coco_json, load_yolo_seg, semantic_mask, split_holdout

CLASSES = ("background", "person", "chair")


def _yolo_dir(tmp_path: Path) -> Path:
    (tmp_path / "images" / "train").mkdir(parents=True)
    (tmp_path / "labels" / "train").mkdir(parents=True)
    cv2.imwrite(str(tmp_path / "images" / "train" / "a.jpg"), np.zeros((100, 200, 3), np.uint8))
    # person: a square from (0.1, 0.2) to (0.5, 0.8); a car (id 2) that must be dropped; a chair triangle.
    (tmp_path / "labels" / "train" / "a.txt").write_text(
        "0 0.1 0.2 0.5 0.2 0.5 0.8 0.1 0.8\n2 0.6 0.1 0.9 0.1 0.9 0.3\n56 0.6 0.9 0.9 0.9 0.75 0.5\n")
    return tmp_path


def test_yolo_seg_polygon_parsing(tmp_path: Path) -> None:
    items = load_yolo_seg(_yolo_dir(tmp_path), {0: "person", 56: "chair"})
    assert len(items) == 1 and items[0].size == (100, 200)
    labels = [i.label for i in items[0].instances]
    assert labels == ["person", "chair"]
    np.testing.assert_allclose(items[0].instances[0].polygons[0][0], [20.0, 20.0])
    sem = semantic_mask(items[0], CLASSES)
    assert sem[50, 60] == 1 and sem[85, 150] == 2 and sem[5, 5] == 0 and sem[20, 150] == 0
    assert abs((sem == 1).sum() - 80 * 60) < 300


def test_yolo_seg_malformed_line(tmp_path: Path) -> None:
    root = _yolo_dir(tmp_path)
    (root / "labels" / "train" / "a.txt").write_text("0 0.1 0.2 0.5\n")
    with pytest.raises(SequenceFormatError, match="a.txt:1"):
        load_yolo_seg(root, {0: "person"})


def test_coco_json(tmp_path: Path) -> None:
    cv2.imwrite(str(tmp_path / "x.jpg"), np.zeros((50, 60, 3), np.uint8))
    ann = {"images": [{"id": 7, "file_name": "x.jpg", "height": 50, "width": 60}],
           "categories": [{"id": 1, "name": "person"}, {"id": 62, "name": "chair"}, {"id": 3, "name": "car"}],
           "annotations": [{"image_id": 7, "category_id": 1, "segmentation": [[10, 10, 30, 10, 30, 40, 10, 40]]},
                           {"image_id": 7, "category_id": 3, "segmentation": [[0, 0, 5, 0, 5, 5]]},
                           {"image_id": 7, "category_id": 62, "segmentation": {"counts": "rle", "size": [50, 60]}}]}
    path = tmp_path / "instances.json"
    path.write_text(json.dumps(ann))
    items = load_coco_json(path, tmp_path, {"person": "person", "chair": "chair"})
    assert [i.label for i in items[0].instances] == ["person"]
    assert semantic_mask(items[0], CLASSES)[20, 20] == 1


def test_holdout_split_is_deterministic(tmp_path: Path) -> None:
    from worker.slam.segmentation.train.datasets import LabelledImage

    items = [LabelledImage(Path(f"{i:03d}.jpg"), (1, 1)) for i in range(10)]
    train, held = split_holdout(list(reversed(items)), 5)
    assert [h.image.name for h in held] == ["000.jpg", "005.jpg"] and len(train) == 8
