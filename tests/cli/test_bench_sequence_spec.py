"""The benchmarks' `DIR[:CAMERA]` arguments (bench/sequence_spec.py): a folder alone uses its camera.json, a
JSON camera keeps its own colons."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

from sequence_spec import camera_of, split_spec  # noqa: E402


def test_a_folder_alone_leaves_the_camera_to_its_camera_json():
    assert split_spec("/data/synth_s0") == ("/data/synth_s0", None)
    assert split_spec("/data/synth_s0:") == ("/data/synth_s0", None)
    assert camera_of(None) is None


def test_a_preset_after_the_last_colon():
    folder, camera = split_spec("/data/bonn_crowd_dev:bonn")
    assert folder == "/data/bonn_crowd_dev"
    assert camera_of(camera).name == "bonn"


def test_a_json_camera_keeps_its_colons():
    text = json.dumps({"fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0, "depth_scale": 1000.0,
                       "width": 640, "height": 480})
    folder, camera = split_spec(f"/data/seq:{text}")
    assert folder == "/data/seq"
    assert camera_of(camera).fx == pytest.approx(500.0)
