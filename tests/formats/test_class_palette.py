"""One colour per class name (PASCAL VOC's palette), legends of the classes present, and the class overlay."""
from __future__ import annotations

import numpy as np
import pytest

from formats.class_names import VOC_CLASSES as VOC_NAMES
from formats.class_palette import (
    MOVING_OUTLINE,
    class_colour,
    class_overlay,
    hex_colour,
    legend,
    present_classes,
    voc_palette_colour,
)
from worker.slam.segmentation.classes import VOC_CLASSES


def test_voc_classes_get_the_voc_palette() -> None:
    assert VOC_NAMES == VOC_CLASSES  # the segmenters' class order is the palette's
    assert class_colour("background") == (0, 0, 0)
    assert class_colour("aeroplane") == (128, 0, 0) and class_colour("person") == (192, 128, 128)
    assert class_colour("car") == (128, 128, 128) and class_colour("dog") == (64, 0, 128)
    assert hex_colour("person") == "#c08080"
    assert len({class_colour(c) for c in VOC_CLASSES}) == 21


def test_other_classes_get_a_stable_colour_past_vocs() -> None:
    voc = {class_colour(c) for c in VOC_CLASSES}
    teddy = class_colour("teddy bear")
    assert teddy == class_colour("teddy bear") and teddy not in voc
    assert teddy in {voc_palette_colour(i) for i in range(21, 256)}


def test_legend_lists_the_present_classes_dynamic_first_without_background() -> None:
    got = legend(["background", "chair", "person", "dog", "person"], ["person", "dog"])
    assert [e["name"] for e in got] == ["person", "dog", "chair"]
    assert got[0] == {"name": "person", "colour": "#c08080", "dynamic": True} and got[2]["dynamic"] is False


def test_present_classes_counts_pixels() -> None:
    labels = np.zeros((4, 5), np.uint8)
    labels[0, 0] = 2
    assert present_classes(labels, ("background", "person", "chair")) == ("background", "chair")


def test_overlay_tints_dynamic_classes_strongly_static_faintly_and_outlines_moving() -> None:
    rgb = np.full((40, 40, 3), 100, np.uint8)
    labels = np.zeros((40, 40), np.uint8)
    labels[5:25, 5:25] = 1  # person, dynamic
    labels[30:38, 30:38] = 2  # chair, not dynamic
    moving = np.zeros((40, 40), bool)
    moving[5:25, 5:25] = True
    out = class_overlay(rgb, labels, ("background", "person", "chair"), ("person",), moving, alpha=0.5, faint=0.2)
    assert (out[0, 0] == 100).all()  # background untouched
    assert out[15, 15].tolist() == [146, 114, 114]  # (100 + 192) / 2, (100 + 128) / 2: person's colour at 0.5
    chair = np.array(class_colour("chair"), float)
    assert out[34, 34].tolist() == np.floor(0.8 * 100 + 0.2 * chair + 0.5).astype(int).tolist()
    assert out[5, 15].tolist() == list(MOVING_OUTLINE) and out[6, 15].tolist() == list(MOVING_OUTLINE)
    assert out[7, 15].tolist() == [146, 114, 114]  # the outline is 2 px wide, inside the moving region
    assert out.dtype == np.uint8 and (rgb == 100).all()  # a new image
    with pytest.raises(ValueError, match="do not match"):
        class_overlay(rgb, labels[:10], ("background", "person"), ("person",))
