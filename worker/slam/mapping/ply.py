"""Binary little-endian PLY of a coloured point cloud (x y z float32, red green blue uint8)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from worker.slam.errors import SequenceFormatError

_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])


def write_ply(path: Path | str, xyz: np.ndarray, rgb: np.ndarray) -> None:
    """Write (N,3) float points and (N,3) uint8 RGB colours atomically (temp file + rename)."""
    path = Path(path)
    data = np.empty(len(xyz), _DTYPE)
    data["x"], data["y"], data["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    data["red"], data["green"], data["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    header = ("ply\nformat binary_little_endian 1.0\ncomment VTD-SLAM dense map, world frame, metres\n"
              f"element vertex {len(xyz)}\nproperty float x\nproperty float y\nproperty float z\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    tmp = path.with_name(path.name + ".part")
    with tmp.open("wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(data.tobytes())
    tmp.replace(path)


def read_ply(path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Read what `write_ply` writes: (N,3) float32 points, (N,3) uint8 colours."""
    path = Path(path)
    raw = path.read_bytes()
    end = raw.find(b"end_header\n")
    if not raw.startswith(b"ply\n") or end < 0:
        raise SequenceFormatError("not a PLY file", path=path)
    header = raw[:end].decode("ascii", "replace").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise SequenceFormatError("only binary little-endian PLY is supported", path=path)
    n = next(int(line.split()[2]) for line in header if line.startswith("element vertex"))
    data = np.frombuffer(raw, _DTYPE, count=n, offset=end + len(b"end_header\n"))
    xyz = np.column_stack([data["x"], data["y"], data["z"]])
    return xyz, np.column_stack([data["red"], data["green"], data["blue"]])
