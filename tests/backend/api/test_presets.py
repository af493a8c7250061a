"""The api's preset names come from formats.catalog, the same list the pipeline builds from; camera specs parse."""
from __future__ import annotations

import pytest

from formats import catalog
from storage.errors import InvalidInput
from storage.presets import (
    CAMERA_PRESETS,
    DEFAULT_PIPELINE_PRESET,
    PIPELINE_PRESETS,
    check_preset,
    parse_camera_spec,
)


def test_the_pipeline_builds_every_catalog_preset():
    from worker.slam.presets import default_preset, describe_presets, get_preset

    assert describe_presets() == {p.name: p.description for p in catalog.PIPELINE_PRESETS}
    assert list(PIPELINE_PRESETS) == [p.name for p in catalog.PIPELINE_PRESETS]
    assert DEFAULT_PIPELINE_PRESET == default_preset() == "full"
    for spec in catalog.PIPELINE_PRESETS:
        cfg = get_preset(spec.name)
        assert cfg.name == spec.name and cfg.stages == list(spec.stages)


def test_the_pipeline_cameras_are_the_catalog_cameras():
    from worker.slam.camera import PRESETS

    assert sorted(CAMERA_PRESETS) == sorted(PRESETS) == sorted(catalog.CAMERA_PRESETS)
    assert {(c.width, c.height) for c in PRESETS.values()} == {(640, 480)}  # storage.ingest assumes it
    tum1 = PRESETS["tum1"]
    assert (tum1.fx, tum1.depth_scale, tum1.dist[4], tum1.name) == (517.3, 5000.0, 1.1633, "tum1")


def test_camera_specs():
    assert parse_camera_spec("tum3") == {"preset": "tum3"}
    assert parse_camera_spec('{"fx": 500, "fy": 500, "cx": 320, "cy": 240, "dist": [0, 0, 0, 0]}') == {
        "fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0, "dist": [0.0, 0.0, 0.0, 0.0]}
    assert parse_camera_spec('{"fx": 500, "fy": 500, "cx": 320, "cy": 240, "depth_registered": false}') == {
        "fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0, "depth_registered": False}
    for bad in ["tum9", "{", '{"fx": 1}', '{"fx": -1, "fy": 1, "cx": 1, "cy": 1}', '{"fx": 1, "fy": 1, "cx": 1, '
                '"cy": 1, "zoom": 2}', "[1, 2]", '{"fx": true, "fy": 1, "cx": 1, "cy": 1}']:
        with pytest.raises(InvalidInput):
            parse_camera_spec(bad)
    with pytest.raises(InvalidInput, match="orb-only"):
        check_preset("everything")
