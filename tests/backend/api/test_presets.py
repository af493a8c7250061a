"""The api's preset mirrors (storage.presets) equal the pipeline's registries, and camera specs parse."""
from __future__ import annotations

import pytest

from storage.errors import InvalidInput
from storage.presets import (
    CAMERA_PRESETS,
    DEFAULT_PIPELINE_PRESET,
    PIPELINE_PRESETS,
    check_preset,
    parse_camera_spec,
)


def test_pipeline_presets_mirror_the_pipeline_registry():
    import worker.slam.pipeline  # noqa: F401 - registers every stage/preset the pipeline ships
    from worker.slam.config import default_preset, preset_names

    assert sorted(PIPELINE_PRESETS) == preset_names(), "update storage/presets.py PIPELINE_PRESETS"
    assert DEFAULT_PIPELINE_PRESET == default_preset(), "update storage/presets.py DEFAULT_PIPELINE_PRESET"


def test_camera_presets_mirror_the_camera_registry():
    from worker.slam.camera import PRESETS

    assert sorted(CAMERA_PRESETS) == sorted(PRESETS), "update storage/presets.py CAMERA_PRESETS"
    assert {(c.width, c.height) for c in PRESETS.values()} == {(640, 480)}  # storage.ingest assumes it


def test_camera_specs():
    assert parse_camera_spec("tum3") == {"preset": "tum3"}
    assert parse_camera_spec('{"fx": 500, "fy": 500, "cx": 320, "cy": 240, "dist": [0, 0, 0, 0]}') == {
        "fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0, "dist": [0.0, 0.0, 0.0, 0.0]}
    for bad in ["tum9", "{", '{"fx": 1}', '{"fx": -1, "fy": 1, "cx": 1, "cy": 1}', '{"fx": 1, "fy": 1, "cx": 1, '
                '"cy": 1, "zoom": 2}', "[1, 2]", '{"fx": true, "fy": 1, "cx": 1, "cy": 1}']:
        with pytest.raises(InvalidInput):
            parse_camera_spec(bad)
    with pytest.raises(InvalidInput, match="orb-only"):
        check_preset("everything")
