"""PLY point clouds: written as binary little-endian ``x y z`` float32 + ``red green blue`` uint8 (the dense map);
read back from any binary little-endian PLY whose vertices have float or double x y z (colours optional)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from formats.errors import FormatError

_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
_TYPES = {"float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8", "uchar": "u1", "uint8": "u1",
          "char": "i1", "int8": "i1", "ushort": "<u2", "uint16": "<u2", "short": "<i2", "int16": "<i2",
          "uint": "<u4", "uint32": "<u4", "int": "<i4", "int32": "<i4"}
_END = b"end_header\n"
MAX_HEADER_BYTES = 64 * 1024


def write_ply(path: Path | str, xyz: np.ndarray, rgb: np.ndarray) -> None:
    """Write (N, 3) points (world frame, metres) and (N, 3) uint8 RGB colours atomically (temp file + rename)."""
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


def read_ply(path: Path | str) -> tuple[np.ndarray, np.ndarray | None]:
    """(N, 3) float32 points and (N, 3) uint8 colours (None when the file has none) of the vertex element,
    which must be the first element."""
    path = Path(path)
    with path.open("rb") as fh:
        head = fh.read(MAX_HEADER_BYTES)
        end = head.find(_END)
        if not head.startswith(b"ply\n") or end < 0:
            raise FormatError("not a PLY file (or its header is too long)", path=path)
        header = head[:end].decode("ascii", "replace").splitlines()
        if "format binary_little_endian 1.0" not in header:
            raise FormatError("only binary little-endian PLY is supported", path=path)
        count, props = _vertex_layout(header, path)
        fh.seek(end + len(_END))
        dtype = np.dtype(props)
        raw = fh.read(count * dtype.itemsize)
    if len(raw) < count * dtype.itemsize:
        raise FormatError(f"ends before its {count} vertices", path=path)
    data = np.frombuffer(raw, dtype=dtype, count=count)
    names = dtype.names or ()
    if not {"x", "y", "z"} <= set(names):
        raise FormatError("vertices have no x y z", path=path)
    xyz = np.column_stack([data["x"], data["y"], data["z"]]).astype(np.float32)
    if not {"red", "green", "blue"} <= set(names):
        return xyz, None
    return xyz, np.column_stack([data["red"], data["green"], data["blue"]]).astype(np.uint8)


def _vertex_layout(header: list[str], path: Path) -> tuple[int, list[tuple[str, str]]]:
    count, props, in_vertex = -1, [], False
    for line in header:
        parts = line.split()
        if parts[:1] == ["element"]:
            if count >= 0:
                break  # the vertex element is read; later elements (faces) are not
            if len(parts) != 3 or parts[1] != "vertex" or not parts[2].isdigit():
                raise FormatError(f"expected 'element vertex N' first, got {line[:80]!r}", path=path)
            count, in_vertex = int(parts[2]), True
        elif parts[:1] == ["property"] and in_vertex:
            if len(parts) != 3 or parts[1] not in _TYPES:
                raise FormatError(f"unsupported vertex property {line[:80]!r}", path=path)
            props.append((parts[2], _TYPES[parts[1]]))
    if count < 0:
        raise FormatError("has no vertex element", path=path)
    return count, props
