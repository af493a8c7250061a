from pathlib import Path

import numpy as np
import pytest

from formats.errors import FormatError
from formats.ply import read_ply, write_ply


def test_round_trip(tmp_path: Path):
    rng = np.random.default_rng(0)
    xyz = rng.normal(size=(100, 3)).astype(np.float32)
    rgb = rng.integers(0, 256, (100, 3), dtype=np.uint8)
    write_ply(tmp_path / "m.ply", xyz, rgb)
    back_xyz, back_rgb = read_ply(tmp_path / "m.ply")
    np.testing.assert_array_equal(back_xyz, xyz)
    np.testing.assert_array_equal(back_rgb, rgb)


def test_reads_double_points_without_colour_and_stops_at_faces(tmp_path: Path):
    pts = np.arange(6, dtype="<f8").reshape(2, 3)
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
              b"property double z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n")
    (tmp_path / "d.ply").write_bytes(header + pts.tobytes())
    xyz, rgb = read_ply(tmp_path / "d.ply")
    assert rgb is None and xyz.dtype == np.float32
    np.testing.assert_array_equal(xyz, pts)


@pytest.mark.parametrize(("data", "message"), [
    (b"not a ply", "not a PLY"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0 0 0\n", "little-endian"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
     b"property float z\nend_header\n\x00\x00", "ends before"),
    (b"ply\nformat binary_little_endian 1.0\nend_header\n", "no vertex"),
])
def test_malformed(tmp_path: Path, data: bytes, message: str):
    (tmp_path / "bad.ply").write_bytes(data)
    with pytest.raises(FormatError, match=message):
        read_ply(tmp_path / "bad.ply")
