"""The stage contracts: the shipped presets' stage lists pass, wrong orders are refused naming stage and input."""
from __future__ import annotations

import pytest

from formats.catalog import PIPELINE_PRESETS, STAGE_CONTRACTS, StageOrderError, check_stage_order, provided_before


@pytest.mark.parametrize("preset", PIPELINE_PRESETS, ids=lambda p: p.name)
def test_every_shipped_preset_passes(preset) -> None:
    check_stage_order(preset.stages)


@pytest.mark.parametrize("stages, match", [
    (["restoration"], r"'restoration' needs dynamic_mask, which no earlier stage provides; list 'culling'"),
    (["segmentation", "restoration", "culling"], r"'restoration' needs dynamic_mask, which 'culling' provides only"),
    (["culling", "segmentation"], r"'culling' uses potentially_dynamic, which 'segmentation' provides only after"),
    (["culling", "culling"], r"'culling' is listed twice"),
    (["segmentation", "warp"], r"unknown pipeline stage 'warp'; known: segmentation, culling, restoration"),
])
def test_wrong_orders_are_refused_with_a_clear_message(stages, match) -> None:
    with pytest.raises(StageOrderError, match=match) as err:
        check_stage_order(stages)
    assert err.value.detail["stage"] in stages


def test_culling_alone_and_without_restoration_pass() -> None:
    check_stage_order(["culling", "restoration"])
    check_stage_order(["segmentation"])
    check_stage_order([])


def test_provided_before() -> None:
    assert provided_before(["segmentation", "culling"], "culling") == {"potentially_dynamic", "class_labels"}
    assert provided_before(["culling"], "culling") == frozenset()
    # not listed: all
    assert provided_before(["segmentation", "unknown"], "culling") == {"potentially_dynamic", "class_labels"}
    assert list(STAGE_CONTRACTS) == ["segmentation", "culling", "restoration"]
