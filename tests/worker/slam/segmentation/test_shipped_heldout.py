"""The shipped checkpoint on the real held-out person sets (`segmentation/heldout.py`, 318 images).

Two kinds of check: regression floors a little below what the shipped checkpoint measured on 2026-12-02
(weights/MODEL_CARD.md, "Held-out real images"), so a worse checkpoint fails; and issue 20's targets, each a
strict xfail while the shipped checkpoint misses it, so a checkpoint that meets one fails here until its marker
is removed (the card's figures must then be updated too).
"""
from __future__ import annotations

from pathlib import Path

import pytest

from worker.slam.segmentation import SegmenterConfig, make_segmenter
from worker.slam.segmentation.heldout import PersonScores, build_sets, score_set

BELOW = pytest.mark.xfail(strict=True, reason="issue 20 target: the shipped checkpoint is below it")


@pytest.fixture(scope="module")
def scores(shared: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, PersonScores]:
    sets = build_sets(shared, tmp_path_factory.mktemp("bonn_refs"))
    assert sum(len(s.images) for s in sets) >= 300
    seg = make_segmenter(SegmenterConfig(device="cpu", threads=1))
    return {s.name: score_set(seg, s) for s in sets}


@pytest.mark.realdata
@pytest.mark.slow
def test_shipped_msnet_regression_floors(scores: dict[str, PersonScores]) -> None:
    """Measured 2026-12-05 (the `cpu-real-mnv2` checkpoint, its CNN path started from the teacher's MobileNetV2):
    COCO held-out IoU 0.443, CCP test 0.865, walking_xyz 0.790, Bonn precision 0.931 / recall 0.957, 7-Scenes
    0.01 % of pixels marked (the checkpoint before it: 0.286, 0.730, 0.640, 0.772 / 0.806, 0.00 %)."""
    assert scores["coco-heldout"].iou is not None and scores["coco-heldout"].iou >= 0.42
    assert scores["ccp-test"].iou is not None and scores["ccp-test"].iou >= 0.84
    assert scores["tum-walking-xyz"].iou is not None and scores["tum-walking-xyz"].iou >= 0.77
    bonn = scores["bonn-crowd"]
    assert bonn.precision is not None and bonn.recall is not None
    assert bonn.precision >= 0.91 and bonn.recall >= 0.93
    assert scores["7scenes-empty"].marked <= 0.002


ISSUE_TARGETS = [
    pytest.param("ccp-test", "iou", 0.85, id="ccp-iou"),
    pytest.param("coco-heldout", "iou", 0.60, marks=BELOW, id="coco-iou"),
    pytest.param("tum-walking-xyz", "iou", 0.75, id="walking-xyz-iou"),
    pytest.param("bonn-crowd", "precision", 0.85, id="bonn-precision"),
    pytest.param("bonn-crowd", "recall", 0.85, id="bonn-recall"),
]


@pytest.mark.realdata
@pytest.mark.slow
@pytest.mark.parametrize(("name", "field", "floor"), ISSUE_TARGETS)
def test_issue_20_targets(scores: dict[str, PersonScores], name: str, field: str, floor: float) -> None:
    value = getattr(scores[name], field)
    assert value is not None and value >= floor, f"{name} {field} {value} < {floor}"


@pytest.mark.realdata
@pytest.mark.slow
def test_issue_20_marked_area_on_people_free_frames(scores: dict[str, PersonScores]) -> None:
    """Target <= 1 % of pixels (goal 0.2 %): 0.01 %. Frames 900-999 are held out by `cpu-real-mnv2` (and were
    never seen by the checkpoint's starting weights, the teacher's MobileNetV2)."""
    assert scores["7scenes-empty"].marked <= 0.01
