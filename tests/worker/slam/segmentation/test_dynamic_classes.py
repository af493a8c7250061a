"""A job's potentially dynamic classes by name or group, resolved for both backends; the teacher's 21 classes."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from formats.class_palette import class_colour, class_overlay
from tests.worker.slam.segmentation.test_msnet_model import TINY
from worker.slam.errors import ConfigError
from worker.slam.io.images import read_rgb
from worker.slam.presets import get_preset
from worker.slam.segmentation import SegmenterConfig, make_segmenter
from worker.slam.segmentation.classes import DEFAULT_DYNAMIC, VOC_CLASSES
from worker.slam.segmentation.dynamic_names import resolve_for_segmenter
from worker.slam.segmentation.msnet import build_msnet
from worker.slam.segmentation.msnet.checkpoint import save_model

TEACHER = "models/deeplabv3_257_mv_gpu.tflite"
DOG_IMAGE = "data/coco128_seg/images/train2017/000000000581.jpg"  # a dog (COCO 16) and a person the teacher sees


def test_config_takes_lists_and_comma_strings_and_refuses_unknown_names() -> None:
    assert SegmenterConfig(dynamic_classes=["person", "vehicle"]).dynamic_classes == ("person", "vehicle")  # type: ignore[arg-type]
    assert SegmenterConfig(dynamic_classes="animal, car").dynamic_classes == ("animal", "car")  # type: ignore[arg-type]
    assert SegmenterConfig().dynamic_classes is None and SegmenterConfig(dynamic_classes=()).dynamic_classes == ()
    with pytest.raises(ValueError, match="unknown potentially dynamic class 'forklift'"):
        SegmenterConfig(dynamic_classes=("person", "forklift"))
    # a job's config snapshot: the override arrives as a JSON list
    cfg = get_preset("no-restoration", {"segmentation": {"segmenter": {"dynamic_classes": ["animal"]}}})
    assert cfg.section("segmentation").segmenter.dynamic_classes == ("animal",)
    with pytest.raises(ConfigError, match="forklift"):
        get_preset("no-restoration", {"segmentation.segmenter.dynamic_classes": ["forklift"]})


def test_names_resolve_against_the_segmenters_classes() -> None:
    voc, small = VOC_CLASSES, ("background", "person", "chair")
    assert resolve_for_segmenter(["vehicle"], voc) == ("aeroplane", "bicycle", "boat", "bus", "car", "motorbike",
                                                       "train")
    assert resolve_for_segmenter(["motorcycle", "couch", "tv"], voc) == ("motorbike", "sofa", "tvmonitor")
    assert resolve_for_segmenter(["person", "vehicle", "teddy bear"], small) == ("person",)  # not covered: dropped
    assert resolve_for_segmenter(["object"], small) == ("chair",)
    assert resolve_for_segmenter(["teddy bear"], (*voc, "teddy bear")) == ("teddy bear",)  # a checkpoint's own
    with pytest.raises(ConfigError, match="unicorn"):
        resolve_for_segmenter(["unicorn"], voc)


def test_msnet_gets_the_resolved_names(tmp_path: Path) -> None:
    path = tmp_path / "tiny.pt"
    save_model(path, build_msnet(TINY), {"note": "test"})
    base = SegmenterConfig(checkpoint=str(path), device="cpu")
    seg = make_segmenter(base)
    assert seg.classes == ("background", "person", "chair") and seg.dynamic_classes == ("person", "chair")
    assert make_segmenter(replace(base, dynamic_classes=("vehicle", "person"))).dynamic_classes == ("person",)
    seg = make_segmenter(replace(base, dynamic_classes=("object", "vehicle")))
    assert seg.dynamic_classes == ("chair",)
    res = seg.segment(np.zeros((48, 64, 3), np.uint8))
    assert res.dynamic_classes == ("chair",)
    assert (res.dynamic_mask() == (res.labels == 2)).all()


@pytest.fixture(scope="module")
def teacher(shared: Path) -> SegmenterConfig:
    return SegmenterConfig(backend="tflite-teacher", model_path=str(shared / TEACHER), full_voc=True)


def test_teacher_full_voc_gives_21_classes_and_colours_a_real_dog(shared: Path, teacher: SegmenterConfig) -> None:
    seg = make_segmenter(teacher)
    assert seg.classes == VOC_CLASSES and seg.dynamic_classes == DEFAULT_DYNAMIC
    assert make_segmenter(replace(teacher, full_voc=False)).classes == ("background", "person", "chair")
    rgb = read_rgb(shared / DOG_IMAGE)
    res = seg.segment(rgb)
    dog = res.class_mask("dog")
    truth = _coco_mask(shared / DOG_IMAGE, rgb.shape[:2], coco_id=16)
    assert dog.sum() > 0.05 * dog.size and (dog & truth).sum() > 0.7 * dog.sum()  # the teacher's dog is COCO's dog
    assert res.dynamic_mask()[dog].all()  # animals are potentially dynamic by default
    out = class_overlay(rgb, res.labels, res.classes, res.dynamic_classes)
    tint = out[dog].astype(float) - rgb[dog].astype(float)  # = alpha * (dog colour - pixel)
    want = np.array(class_colour("dog"), float) - rgb[dog].astype(float)
    assert np.corrcoef(tint.ravel(), want.ravel())[0, 1] > 0.99
    only_people = make_segmenter(replace(teacher, dynamic_classes=("person",)))
    assert only_people.dynamic_classes == ("person",) and not only_people.segment(rgb).dynamic_mask()[dog].any()


def _coco_mask(image: Path, hw: tuple[int, int], coco_id: int) -> np.ndarray:
    """(H, W) bool union of the image's COCO128 polygons of one class (YOLO-seg: normalised x y pairs)."""
    label = image.parents[2] / "labels" / image.parent.name / (image.stem + ".txt")
    mask = np.zeros(hw, np.uint8)
    for line in label.read_text().splitlines():
        vals = line.split()
        if vals and int(vals[0]) == coco_id:
            pts = np.array(vals[1:], float).reshape(-1, 2) * (hw[1], hw[0])
            cv2.fillPoly(mask, [pts.round().astype(np.int32)], 1)
    return mask > 0
