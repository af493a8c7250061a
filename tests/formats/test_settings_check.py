"""formats.settings_check: the one rule book of a setting's type, range and pairs, the same on both sides of
the api/worker wall (the api through storage.config_ranges, the worker through PipelineConfig)."""
from __future__ import annotations

import math

import pytest

from formats.errors import SpecError, VtdError
from formats.settings_check import check_config, check_pair, check_setting, kind_of, settings_ranges
from storage.config_ranges import check_ranges
from storage.errors import InvalidInput
from worker.slam.config import PipelineConfig
from worker.slam.errors import ConfigError


@pytest.mark.parametrize(("value", "kind", "bounds", "want"), [
    (8, "int", (1, 16), 8), (8.0, "int", (1, 16), 8), (0.5, "float", (0.1, 1.0), 0.5), (1, "float", None, 1.0),
    (True, "bool", None, True), ("yes", "bool", None, True), ("0", "bool", None, False), ("points", "str", None,
                                                                                        "points"),
    (None, "null", None, None), ([1, 2], "list", None, [1, 2]),
])
def test_valid_values_come_back_normalised(value, kind, bounds, want) -> None:
    got = check_setting("s.k", value, kind, bounds)
    assert got == want and type(got) is type(want)


@pytest.mark.parametrize(("value", "kind", "bounds", "words"), [
    (2.5, "int", (1, 16), "must be an integer within 1..16"), ("8", "int", (1, 16), "must be an integer"),
    (True, "int", None, "must be an integer"), (math.nan, "float", (0, 1), "must be a finite number within 0..1"),
    (math.inf, "float", None, "must be a finite number"), ("1.5", "float", None, "must be a finite number"),
    (1, "bool", None, "must be true or false"), ("maybe", "bool", None, "must be true or false"),
    (5, "str", None, "must be a string"),
    (0, "int", (1, 16), "must be within 1..16, got 0"), (7, "float", (0.1, 1.0), "must be within 0.1..1.0"),
])
def test_wrong_types_and_ranges_name_the_field(value, kind, bounds, words) -> None:
    with pytest.raises(SpecError, match="config s.k " + words.replace(".", r"\.")) as info:
        check_setting("s.k", value, kind, bounds)
    assert info.value.detail["field"] == "s.k" and isinstance(info.value, VtdError)
    if bounds is not None:
        assert (info.value.detail["min"], info.value.detail["max"]) == bounds


def test_pairs_below_and_at_most() -> None:
    check_pair("below", "a.lo", 1, "a.hi", 2)
    check_pair("at_most", "a.lo", 2, "a.hi", 2)
    with pytest.raises(SpecError, match=r"a\.lo \(2\) must be below a\.hi \(2\)") as info:
        check_pair("below", "a.lo", 2, "a.hi", 2)
    assert info.value.detail == {"field": "a.lo", "fields": ["a.lo", "a.hi"], "values": [2, 2]}
    with pytest.raises(SpecError, match="must be at most"):
        check_pair("at_most", "a.lo", 3, "a.hi", 2)


def test_kind_of_a_default() -> None:
    defaults: tuple[object, ...] = (True, 1, 1.0, "x", None, (1,), [1], {}, 1j)
    got = [kind_of(v) for v in defaults]
    assert got == ["bool", "int", "float", "str", "null", "list", "list", "dict", "complex"]
    assert check_setting("a.b", [1, "x"], kind_of((1,))) == [1, "x"]  # published, not checked


@pytest.mark.parametrize("bad", [
    {"features.n_levels": 0}, {"features": {"n_levels": "8"}}, {"dense.enabled": 1}, {"dense.method": 3},
    {"features.min_depth_m": 7.0}, {"tracking": {"nonsense": 1}},
])
def test_api_and_worker_refuse_the_same_configs_with_the_same_message(bad) -> None:
    with pytest.raises(InvalidInput) as api:
        check_ranges(bad)
    with pytest.raises(ConfigError) as worker:
        PipelineConfig().with_overrides(bad)
    assert isinstance(api.value.__cause__, SpecError) or "unknown" in api.value.message
    if "unknown" not in api.value.message:
        assert api.value.message == worker.value.message


def test_the_published_defaults_pass() -> None:
    ranges = settings_ranges()
    check_config({key: spec["default"] for key, spec in ranges.items()})
    assert PipelineConfig().with_overrides({"dense.enabled": "false"}).to_dict()["dense"]["enabled"] is False


def test_a_list_setting_takes_only_its_choices() -> None:
    from formats.settings_check import check_choices

    specs = {"seg.names": {"type": "null", "default": None, "choices": ["person", "vehicle", "car"]}}
    for ok in (None, [], ["person", "car"], "vehicle, car", {"seg": {"names": ["vehicle"]}}):
        check_config(ok if isinstance(ok, dict) else {"seg.names": ok}, specs)
    for bad, fragment in ((["person", "forklift"], "unknown name 'forklift'"), ("car,boat", "unknown name 'boat'"),
                          ([1], "a list of names"), (5, "a list of names")):
        with pytest.raises(SpecError, match=fragment) as err:
            check_config({"seg.names": bad}, specs)
        assert err.value.detail["field"] == "seg.names"
    check_choices("seg.names", ["car"], ["car"])


def test_the_published_dynamic_classes_choices_are_groups_voc_and_coco_names() -> None:
    from formats.class_names import COCO_CLASSES
    from worker.slam.segmentation.classes import DYNAMIC_GROUPS, VOC_CLASSES

    choices = settings_ranges()["segmentation.segmenter.dynamic_classes"]["choices"]
    assert set(choices) == set(DYNAMIC_GROUPS) | set(VOC_CLASSES[1:]) | set(COCO_CLASSES)
