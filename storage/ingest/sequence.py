"""Validating a TUM-layout sequence folder before it is accepted (stdlib only: the api stays light).

Mirrors what the worker's reader will demand (``worker.slam.io``): ``rgb.txt`` and ``depth.txt`` of
``timestamp relative/path`` lines, every listed file present inside the folder, colour/depth pairs
associated like TUM's associate.py, an optional ``groundtruth.txt`` (``t tx ty tz qx qy qz qw``) and
``camera.json``, and a sample of images verified: 8-bit colour, 16-bit single-channel PNG depth, one size.
"""

from __future__ import annotations

import bisect
import json
import math
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

from storage.errors import InvalidInput
from storage.ingest.images import check_image
from storage.presets import check_intrinsics

MAX_DIFF_S = 0.02
PRESET_SIZE = (640, 480)  # every camera preset (storage.presets.CAMERA_PRESETS) is 640x480
MAX_LIST_BYTES = 64 * 1024 * 1024


@dataclass(frozen=True, slots=True)
class SequenceInfo:
    """What the api stores and shows about an accepted sequence."""

    frames: int
    duration_s: float
    has_groundtruth: bool
    gt_poses: int
    width: int
    height: int
    rgb_listed: int
    depth_listed: int
    files: int
    size_bytes: int
    thumbnail: str
    """Path (relative to the folder) of the first frame's colour image."""
    camera_file: dict[str, Any] | None = None
    sampled: list[int] = field(default_factory=list)

    def meta(self) -> dict[str, Any]:
        return {
            "width": self.width,
            "height": self.height,
            "rgb_listed": self.rgb_listed,
            "depth_listed": self.depth_listed,
            "gt_poses": self.gt_poses,
            "files": self.files,
            "thumbnail": self.thumbnail,
            "camera_file": self.camera_file,
        }


def _err(folder: Path, path: Path, message: str, line: int | None = None) -> InvalidInput:
    rel = path.relative_to(folder).as_posix() if path.is_relative_to(folder) else path.name
    where = f"{rel}:{line}: " if line is not None else f"{rel}: "
    return InvalidInput(where + message, {"file": rel, "line": line})


def _read_text(folder: Path, path: Path) -> str:
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise _err(folder, path, "required file is missing") from None
    if not stat.S_ISREG(st.st_mode):
        raise _err(folder, path, "must be a regular file")
    if st.st_size > MAX_LIST_BYTES:
        raise _err(folder, path, "is too large")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise _err(folder, path, f"not UTF-8 text ({exc.reason})") from None


def read_list(folder: Path, name: str) -> list[tuple[float, str]]:
    """A TUM list file, time-sorted; every listed path must be a regular file inside ``folder``."""
    path = folder / name
    entries: list[tuple[float, str]] = []
    real_folder = folder.resolve()
    inside: dict[PurePosixPath, bool] = {}  # per listed sub-folder: does it stay inside (no symlink out)?
    for lineno, line in enumerate(_read_text(folder, path).splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) < 2:
            raise _err(folder, path, f"expected 'timestamp filename', got {s[:80]!r}", lineno)
        try:
            t = float(parts[0])
        except ValueError:
            raise _err(folder, path, f"timestamp {parts[0][:40]!r} is not a number", lineno) from None
        if not math.isfinite(t):
            raise _err(folder, path, "timestamp is not finite", lineno)
        rel = PurePosixPath(parts[1])
        if rel.is_absolute() or ".." in rel.parts or "\\" in parts[1] or "\x00" in parts[1]:
            raise _err(folder, path, f"path {parts[1][:80]!r} must be relative and stay inside the sequence", lineno)
        try:
            if rel.parent not in inside:  # a symlinked sub-folder of a registered folder may point anywhere
                inside[rel.parent] = folder.joinpath(*rel.parent.parts).resolve().is_relative_to(real_folder)
            st = os.lstat(folder.joinpath(*rel.parts))
        except (FileNotFoundError, NotADirectoryError):
            raise _err(folder, path, f"listed file {parts[1][:80]!r} is missing", lineno) from None
        except (OSError, RuntimeError) as exc:  # name too long, symlink loop (RuntimeError before 3.13), …
            reason = getattr(exc, "strerror", None) or "symlink loop"
            raise _err(folder, path, f"listed file {parts[1][:80]!r} is unusable ({reason})", lineno) from None
        if not inside[rel.parent]:
            raise _err(folder, path, f"listed file {parts[1][:80]!r} lies outside the sequence folder", lineno)
        if not stat.S_ISREG(st.st_mode):
            raise _err(folder, path, f"listed file {parts[1]!r} is not a regular file", lineno)
        entries.append((t, rel.as_posix()))
    if not entries:
        raise _err(folder, path, "lists no frames")
    entries.sort(key=lambda e: e[0])
    return entries


def associate(a: list[float], b: list[float], max_diff: float = MAX_DIFF_S) -> list[tuple[int, int]]:
    """Pairs (i, j) with |a[i] - b[j]| < max_diff, each index once, closest first (TUM associate.py)."""
    order = sorted(range(len(b)), key=lambda k: b[k])
    bs = [b[k] for k in order]
    cand = []
    for i, t in enumerate(a):
        lo, hi = bisect.bisect_left(bs, t - max_diff), bisect.bisect_right(bs, t + max_diff)
        for k in range(lo, hi):
            d = abs(t - bs[k])
            if d < max_diff:
                cand.append((d, i, order[k]))
    cand.sort()
    used_a: set[int] = set()
    used_b: set[int] = set()
    pairs = []
    for _, i, j in cand:
        if i not in used_a and j not in used_b:
            used_a.add(i)
            used_b.add(j)
            pairs.append((i, j))
    pairs.sort()
    return pairs


def read_groundtruth(folder: Path) -> int:
    """Number of poses in ``groundtruth.txt`` (0 when absent); malformed lines are rejected."""
    path = folder / "groundtruth.txt"
    if not path.exists():
        return 0
    n = 0
    for lineno, line in enumerate(_read_text(folder, path).splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.replace(",", " ").split()
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise _err(folder, path, "expected 8 numbers 't tx ty tz qx qy qz qw'", lineno) from None
        if len(values) != 8 or not all(math.isfinite(v) for v in values):
            raise _err(folder, path, "expected 8 finite numbers 't tx ty tz qx qy qz qw'", lineno)
        if sum(q * q for q in values[4:]) < 1e-12:
            raise _err(folder, path, "quaternion is zero", lineno)
        n += 1
    return n


def read_camera_file(folder: Path) -> dict[str, Any] | None:
    path = folder / "camera.json"
    if not path.exists():
        return None
    try:
        data = json.loads(_read_text(folder, path))
    except json.JSONDecodeError as exc:
        raise _err(folder, path, f"not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise _err(folder, path, "must be a JSON object of intrinsics")
    try:
        return check_intrinsics(data)
    except InvalidInput as exc:
        raise _err(folder, path, exc.message) from None


def validate_sequence(folder: Path, camera: dict[str, Any] | None = None, samples: int = 5) -> SequenceInfo:
    """Check ``folder`` is a usable sequence for ``camera`` (a parsed camera spec); raises InvalidInput."""
    rgb = read_list(folder, "rgb.txt")
    depth = read_list(folder, "depth.txt")
    pairs = associate([t for t, _ in rgb], [t for t, _ in depth])
    if not pairs:
        raise _err(folder, folder / "rgb.txt", f"no rgb/depth pairs within {MAX_DIFF_S} s of each other")
    gt_poses = read_groundtruth(folder)
    camera_file = read_camera_file(folder)
    n = len(pairs)
    picks = sorted({round(k * (n - 1) / max(1, samples - 1)) for k in range(min(samples, n))})
    size: tuple[int, int] | None = None
    for k in picks:
        i, j = pairs[k]
        rgb_path, depth_path = folder / rgb[i][1], folder / depth[j][1]
        c = check_image(rgb_path, label=rgb_path.relative_to(folder).as_posix())
        if c.bit_depth != 8 or c.color_type == 4:
            raise _err(folder, rgb_path, "colour images must be 8-bit grey, RGB or RGBA")
        d = check_image(depth_path, label=depth_path.relative_to(folder).as_posix())
        if d.format != "png" or d.bit_depth != 16 or d.channels != 1:
            raise _err(folder, depth_path, "depth images must be 16-bit single-channel PNG")
        if (c.width, c.height) != (d.width, d.height):
            raise _err(folder, depth_path, f"depth is {d.width}x{d.height} but colour is {c.width}x{c.height}")
        if size is not None and size != (c.width, c.height):
            raise _err(folder, rgb_path, f"image is {c.width}x{c.height} but earlier frames are {size[0]}x{size[1]}")
        size = (c.width, c.height)
    assert size is not None
    _check_aspect(folder, size, camera_file or (camera if camera and "preset" not in camera else None))
    files, total = _disk_usage(folder)
    return SequenceInfo(
        frames=n,
        duration_s=round(rgb[pairs[-1][0]][0] - rgb[pairs[0][0]][0], 6),
        has_groundtruth=gt_poses > 0,
        gt_poses=gt_poses,
        width=size[0],
        height=size[1],
        rgb_listed=len(rgb),
        depth_listed=len(depth),
        files=files,
        size_bytes=total,
        thumbnail=rgb[pairs[0][0]][1],
        camera_file=camera_file,
        sampled=picks,
    )


def _check_aspect(folder: Path, size: tuple[int, int], intrinsics: dict[str, Any] | None) -> None:
    """The worker rescales a camera to the image size, but only at the same aspect ratio."""
    w, h = size
    cw, ch = PRESET_SIZE
    if intrinsics is not None:
        cw, ch = intrinsics.get("width", cw), intrinsics.get("height", ch)
    if abs(w / h - cw / ch) > 1e-3:
        raise InvalidInput(
            f"images are {w}x{h} but the camera is {cw}x{ch} (a different aspect ratio)",
            {"image_size": [w, h], "camera_size": [cw, ch]},
        )


def _disk_usage(folder: Path) -> tuple[int, int]:
    files = total = 0
    for root, _dirs, names in os.walk(folder):
        for name in names:
            st = os.lstat(os.path.join(root, name))
            files += 1
            total += st.st_size
    return files, total
