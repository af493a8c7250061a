"""Every core setting has a valid range, checked by the worker and published for the api: the committed
formats/settings_ranges.json is what the config declares, and a setting that crashed a native library
(features.n_levels: 0 segfaulted ORB) is refused with the field and the range, in a subprocess that lives.
Pairs whose ranges each hold but contradict each other (a minimum depth above the maximum) are refused by
both, naming both fields."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from storage.config_ranges import check_ranges
from storage.errors import InvalidInput
from tests.backend.api.data import write_sequence
from worker.slam.catalog import shipped_catalog
from worker.slam.errors import ConfigError
from worker.slam.ranges import RANGES_FILE, render, settings_ranges

CATALOG = shipped_catalog()


def test_the_committed_ranges_file_is_what_the_config_declares() -> None:
    assert RANGES_FILE.read_text(encoding="utf-8") == render(), "run: python -m worker.slam.ranges"


def test_every_numeric_core_setting_has_a_range_holding_its_default() -> None:
    ranges = settings_ranges()
    for section, values in CATALOG.base_config().to_dict().items():
        if section in ("features", "tracking", "mapping", "loop", "dense", "eval"):
            for name, default in values.items():
                if isinstance(default, int | float) and not isinstance(default, bool):
                    spec = ranges[f"{section}.{name}"]
                    assert spec["min"] <= default <= spec["max"] and spec["default"] == default


@pytest.mark.parametrize("key", sorted(k for k, v in settings_ranges().items() if "min" in v))
def test_worker_and_api_refuse_the_same_out_of_range_values(key: str) -> None:
    spec = settings_ranges()[key]
    below = spec["min"] - 1 if spec["type"] == "int" else spec["min"] - abs(spec["min"]) * 0.5 - 1e-3
    for bad in (below, spec["max"] + 1):
        with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            CATALOG.base_config().with_overrides({key: bad})
        with pytest.raises(InvalidInput, match=key.replace(".", r"\.")):
            check_ranges({key: bad})
    for good in (spec["min"], spec["max"]):  # each bound, its pair's other side moved out of the way
        given = {key: good, **_partner_at_its_bound(key, good == spec["max"])}
        check_ranges(given)
        value = CATALOG.base_config().with_overrides(given).to_dict()
    for part in key.split("."):
        value = value[part]
    assert value == good


def _run(seq: Path, out: Path, config: str) -> subprocess.CompletedProcess[str]:
    cmd = [str(Path(sys.executable).parent / "vtdslam"), "run", str(seq), "--out", str(out),
           "--preset", "orb-only", "--quiet", "--config", config]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


def test_n_levels_zero_is_refused_and_extremes_inside_the_ranges_run(tmp_path: Path) -> None:
    seq = write_sequence(tmp_path / "seq", n=4)
    done = _run(seq, tmp_path / "out0", '{"features.n_levels": 0}')
    assert done.returncode > 0, done  # an error exit, not a signal (the segfault was -11)
    assert "features.n_levels must be within 1..16" in done.stdout + done.stderr
    edges = '{"features": {"n_levels": 1, "n_features": 10, "scale_factor": 4.0, "grid_cell_px": 4}}'
    done = _run(seq, tmp_path / "out1", edges)
    assert done.returncode >= 0, done  # the process lives whatever tracking makes of it


def test_the_api_knows_every_setting_not_only_the_ranged_ones() -> None:
    """Booleans, strings and the stage sections' settings pass the api's check; unknown fields do not."""
    snapshot = CATALOG.config_from_dict({}).to_dict()
    check_ranges({k: v for k, v in snapshot.items() if k not in ("name", "stages")})  # every default
    check_ranges({"dense.enabled": False, "dense.method": "tsdf", "loop": {"enabled": False}})
    assert "culling.culling.threshold.d_min" in settings_ranges()
    with pytest.raises(InvalidInput, match="unknown config field 'culling.nope'"):
        check_ranges({"culling.nope": 1})


PAIRS = sorted((lo, spec.get("below") or spec["at_most"], "below" in spec)
               for lo, spec in settings_ranges().items() if "below" in spec or "at_most" in spec)


def _partner_at_its_bound(key: str, high: bool) -> dict[str, float]:
    """The other side of ``key``'s ordered pair at its own extreme, so ``key`` at its bound is consistent."""
    for lo, hi, _strict in PAIRS:
        if key == lo and high:
            return {hi: settings_ranges()[hi]["max"]}
        if key == hi and not high:
            return {lo: settings_ranges()[lo]["min"]}
    return {}


def test_the_ordered_pairs_are_published() -> None:
    assert [(lo, hi) for lo, hi, _ in PAIRS] == [
        ("culling.culling.threshold.d_min", "culling.culling.threshold.d_max"),
        ("features.min_depth_m", "features.max_depth_m"),
        ("restoration.selection.min_refs", "restoration.selection.max_refs"),
        ("restoration.selection.window", "restoration.selection.far_window"),
        ("tracking.keyframe_min_frames", "tracking.keyframe_max_frames"),
    ]


@pytest.mark.parametrize(("lo", "hi", "strict"), PAIRS)
def test_worker_and_api_refuse_pairs_that_contradict_each_other_naming_both(lo: str, hi: str,
                                                                          strict: bool) -> None:
    """Each value inside its own range, the pair out of order: one side given, the other its default, or
    both given (nested or dotted)."""
    default_lo, default_hi = settings_ranges()[lo]["default"], settings_ranges()[hi]["default"]
    step = 1 if settings_ranges()[lo]["type"] == "int" else 0.5
    head, _, field = lo.rpartition(".")
    nested: dict = {field: default_hi + step, hi.rpartition(".")[2]: default_hi}
    for part in reversed(head.split(".")):
        nested = {part: nested}
    hi_min = settings_ranges()[hi]["min"]
    lowered = [{hi: hi_min}] if hi_min < default_lo else []  # only the maximum given, under the minimum
    for bad in ({lo: default_hi + step}, *lowered, nested):
        with pytest.raises(ConfigError) as worker:
            CATALOG.base_config().with_overrides(bad)
        with pytest.raises(InvalidInput) as api:
            check_ranges(bad)
        for err in (worker.value, api.value):
            assert lo in err.message and hi in err.message, err.message
            assert err.detail["fields"] == [lo, hi]
    equal = {lo: default_hi}
    if strict:
        with pytest.raises(ConfigError, match="must be below"):
            CATALOG.base_config().with_overrides(equal)
        with pytest.raises(InvalidInput, match="must be below"):
            check_ranges(equal)
    else:
        check_ranges(equal)
        CATALOG.base_config().with_overrides(equal)
    check_ranges({lo: default_lo, hi: default_hi})  # in order: both sides pass
    CATALOG.base_config().with_overrides({hi: default_hi}).with_overrides({lo: default_lo})


def test_a_pair_is_checked_on_the_whole_config_not_each_override_alone() -> None:
    """A base that moved the maximum down refuses a minimum the defaults would take; a stored snapshot too."""
    base = CATALOG.base_config().with_overrides({"features.max_depth_m": 2.0})
    with pytest.raises(ConfigError, match=r"features\.min_depth_m \(3\.0\) must be below features\.max_depth_m"):
        base.with_overrides({"features": {"min_depth_m": 3.0}})
    snapshot = CATALOG.base_config().to_dict()
    snapshot["tracking"]["keyframe_min_frames"] = snapshot["tracking"]["keyframe_max_frames"] + 1
    with pytest.raises(ConfigError, match="keyframe_min_frames"):
        CATALOG.config_from_dict(snapshot)
