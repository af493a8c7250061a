"""Bad data is found at ingest, not by a job: every frame's image header (not a sample), plausible camera
intrinsics (focal 50-5000 px, principal point inside the image, sane sizes) and ground truth."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from storage.errors import InvalidInput
from storage.ingest.sequence import validate_sequence
from storage.presets import parse_camera_spec
from tests.backend.api.data import CAMERA, write_sequence

N = 20  # the full-data sample is frames 0, 5, 10, 14, 19


@pytest.fixture
def seq(tmp_path: Path) -> Path:
    return write_sequence(tmp_path / "seq", n=N)


def _frame(seq: Path, kind: str, k: int) -> Path:
    return seq / (seq / f"{kind}.txt").read_text().splitlines()[1 + k].split()[1]


def test_an_unsampled_frame_with_an_8_bit_depth_image_is_refused(seq) -> None:
    assert validate_sequence(seq).frames == N
    cv2.imwrite(str(_frame(seq, "depth", 7)), np.zeros((120, 160), np.uint8))
    with pytest.raises(InvalidInput, match="16-bit single-channel"):
        validate_sequence(seq)


def test_an_unsampled_frame_of_another_size_is_refused(seq) -> None:
    cv2.imwrite(str(_frame(seq, "rgb", 8)), np.zeros((60, 80, 3), np.uint8))
    with pytest.raises(InvalidInput, match="80x60"):
        validate_sequence(seq)


@pytest.mark.parametrize("change, fragment", [
    ({"width": 1e15}, "width must be within 16..16384"),
    ({"fx": 1.0}, "fx must be within 50..5000"),
    ({"fy": 1e6}, "fy must be within 50..5000"),
    ({"cx": 500.0}, "cx must lie inside the image"),
    ({"cy": -3.0}, "cy must"),
    ({"depth_scale": 1e-9}, "depth_scale must be within"),
    ({"dist": [1e9, 0, 0, 0]}, "dist coefficients"),
    ({"depth_registered": "no"}, "depth_registered must be true or false"),
])
def test_implausible_intrinsics_are_refused_in_camera_json_and_specs(seq, change, fragment) -> None:
    camera = {**CAMERA, **change}
    with pytest.raises(InvalidInput, match=fragment):
        parse_camera_spec(json.dumps(camera))
    (seq / "camera.json").write_text(json.dumps(camera))
    with pytest.raises(InvalidInput, match=fragment):
        validate_sequence(seq)


@pytest.mark.parametrize("line, fragment", [
    ("100.0 1e200 0 0 0 0 0 1", "within 100000 m"),
    ("100.0 0 0 0 0 0 0 0.5", "unit length"),
    ("100.0 0 0 nan 0 0 0 1", "non-finite"),
])
def test_implausible_ground_truth_is_refused(seq, line, fragment) -> None:
    gt = seq / "groundtruth.txt"
    gt.write_text(gt.read_text() + line + "\n")
    with pytest.raises(InvalidInput, match=fragment):
        validate_sequence(seq)
