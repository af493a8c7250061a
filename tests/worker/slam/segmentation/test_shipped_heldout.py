"""The shipped checkpoint on the real held-out sets (`segmentation/heldout.py`, 526 images with davis_movers_dev).

Two kinds of check: regression floors a little below what the shipped checkpoint measured (weights/MODEL_CARD.md),
so a worse checkpoint fails; and issues 20's and 57's targets, each a strict xfail while the shipped checkpoint
misses it, so a checkpoint that meets one fails here until its marker is removed (the card's figures must then be
updated too).
"""
from __future__ import annotations

from pathlib import Path

import pytest

from worker.slam.segmentation import SegmenterConfig, make_segmenter
from worker.slam.segmentation.heldout import PersonScores, build_sets, score_set

BELOW = pytest.mark.xfail(strict=True, reason="issue 20/57 target: the shipped checkpoint is below it")


@pytest.fixture(scope="module")
def scores(shared: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, PersonScores]:
    sets = build_sets(shared, tmp_path_factory.mktemp("bonn_refs"))
    assert sum(len(s.images) for s in sets) >= 300
    seg = make_segmenter(SegmenterConfig(device="cpu", threads=1))
    return {s.name: score_set(seg, s) for s in sets}


@pytest.mark.realdata
@pytest.mark.slow
def test_shipped_msnet_regression_floors(scores: dict[str, PersonScores]) -> None:
    """Measured 2026-12-06 (the `cpu-voc` checkpoint, 21 VOC classes): COCO held-out person IoU 0.433, CCP test
    0.858, walking_xyz 0.774, Bonn precision 0.918 / recall 0.966, 7-Scenes 1.51 % of pixels marked potentially
    dynamic (real chairs), davis_movers_dev 0.507 (the person checkpoint before it: 0.443, 0.865, 0.790,
    0.931 / 0.957, 0.01 %, 0.342)."""
    assert scores["coco-heldout"].iou is not None and scores["coco-heldout"].iou >= 0.42
    assert scores["ccp-test"].iou is not None and scores["ccp-test"].iou >= 0.84
    assert scores["tum-walking-xyz"].iou is not None and scores["tum-walking-xyz"].iou >= 0.76
    bonn = scores["bonn-crowd"]
    assert bonn.precision is not None and bonn.recall is not None
    assert bonn.precision >= 0.90 and bonn.recall >= 0.94
    assert scores["7scenes-empty"].marked <= 0.02
    davis = scores["davis-movers"]
    assert davis.iou is not None and davis.iou >= 0.48


ISSUE_TARGETS = [
    pytest.param("ccp-test", "iou", 0.85, id="ccp-iou"),
    pytest.param("coco-heldout", "iou", 0.60, marks=BELOW, id="coco-iou"),
    pytest.param("tum-walking-xyz", "iou", 0.75, id="walking-xyz-iou"),
    pytest.param("bonn-crowd", "precision", 0.85, id="bonn-precision"),
    pytest.param("bonn-crowd", "recall", 0.85, id="bonn-recall"),
    pytest.param("davis-movers", "iou", 0.60, marks=BELOW, id="davis-iou"),
]


@pytest.mark.realdata
@pytest.mark.slow
@pytest.mark.parametrize(("name", "field", "floor"), ISSUE_TARGETS)
def test_issue_targets(scores: dict[str, PersonScores], name: str, field: str, floor: float) -> None:
    value = getattr(scores[name], field)
    assert value is not None and value >= floor, f"{name} {field} {value} < {floor}"


@pytest.mark.realdata
@pytest.mark.slow
def test_marked_area_on_people_free_frames(scores: dict[str, PersonScores]) -> None:
    """Issue 57: <= 1 % of pixels marked potentially dynamic (goal 0.2 %). 0.00 % since chairs are no longer
    potentially dynamic by default (1.52 % before, every pixel of it the kitchen's real chairs). Frames 900-999 are
    held out of every recipe's backgrounds."""
    assert scores["7scenes-empty"].marked <= 0.002
