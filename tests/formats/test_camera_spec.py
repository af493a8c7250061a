"""formats.camera_spec: one rule book of explicit intrinsics for the api (upload) and the worker
(`vtdslam run --camera '{...}'`, a folder's camera.json), each answering with its own error class."""
from __future__ import annotations

import json

import pytest

from formats.camera_spec import check_intrinsics
from formats.errors import SpecError
from storage.errors import InvalidInput
from storage.presets import parse_camera_spec
from worker.slam.camera import Camera, parse_camera
from worker.slam.errors import CameraError

GOOD = {"fx": 500, "fy": 500, "cx": 320, "cy": 240}


def test_normalised() -> None:
    got = check_intrinsics({**GOOD, "width": 640.0, "dist": (0.1, 0, 0, 0), "name": "n" * 100})
    assert got["width"] == 640 and isinstance(got["width"], int) and got["fx"] == 500.0
    assert got["dist"] == [0.1, 0.0, 0.0, 0.0] and got["name"] == "n" * 64


@pytest.mark.parametrize(("extra", "words"), [
    ({"fx": 1.0}, "fx must be within 50..5000"), ({"fy": 1e6}, "fy must be within"),
    ({"fx": -1}, "fx must be positive"), ({"fx": "500"}, "fx must be a finite number"),
    ({"cx": 700}, "cx must lie inside the image"), ({"width": 100, "cx": 50, "height": 1e15}, "height must be"),
    ({"width": 640.5}, "width must be an integer"), ({"depth_scale": 0.5}, "depth_scale must be within"),
    ({"dist": [0, 0, 0]}, "4 or 5 numbers"), ({"dist": [0, 0, 0, 20]}, "dist coefficients must be within"),
    ({"depth_registered": "no"}, "depth_registered must be true or false"), ({"f": 1}, "unknown camera fields"),
])
def test_api_and_worker_refuse_the_same_intrinsics(extra, words) -> None:
    spec = {**GOOD, **extra}
    with pytest.raises(SpecError, match=words):
        check_intrinsics(spec)
    with pytest.raises(InvalidInput, match=words):
        parse_camera_spec(json.dumps(spec))
    with pytest.raises(CameraError, match=words):
        parse_camera(json.dumps(spec))


def test_non_finite_distortion() -> None:
    """(The api's JSON parser refuses NaN before the check; the worker's does not.)"""
    with pytest.raises(CameraError, match="dist must be a finite number"):
        parse_camera(json.dumps({**GOOD, "dist": [0, 0, 0, float("nan")]}))


def test_missing_focal_lengths() -> None:
    with pytest.raises(CameraError, match="camera intrinsics need fy, cx"):
        Camera.from_dict({"fx": 500, "cy": 240})


def test_worker_camera_matches_what_the_api_stores() -> None:
    stored = parse_camera_spec(json.dumps({**GOOD, "dist": [0.1, 0, 0, 0], "depth_registered": False}))
    cam = Camera.from_dict(stored)
    assert cam.dist == (0.1, 0.0, 0.0, 0.0, 0.0) and not cam.depth_registered and cam.fx == 500.0
    assert Camera.from_dict(cam.to_dict()) == cam


def test_groundtruth_frame() -> None:
    from formats.camera_spec import groundtruth_frame_of

    assert check_intrinsics({**GOOD, "groundtruth_frame": "bonn-marker"})["groundtruth_frame"] == "bonn-marker"
    with pytest.raises(SpecError, match="groundtruth_frame"):
        check_intrinsics({**GOOD, "groundtruth_frame": "tripod"})
    assert parse_camera({**GOOD, "groundtruth_frame": "bonn-marker"}).groundtruth_frame == "bonn-marker"
    assert parse_camera(dict(GOOD)).groundtruth_frame == "camera"
    assert parse_camera_spec(json.dumps({**GOOD, "groundtruth_frame": "bonn-marker"}))["groundtruth_frame"] \
        == "bonn-marker"
    assert groundtruth_frame_of({"preset": "bonn"}) == "bonn-marker"
    assert groundtruth_frame_of({"preset": "tum3"}) == groundtruth_frame_of(None) == "camera"
    assert groundtruth_frame_of({**GOOD, "groundtruth_frame": "bonn-marker"}) == "bonn-marker"
