"""Validating a TUM-layout sequence folder before it is accepted (stdlib + formats: the api stays light).

Reads the files with the worker's own parsers (``formats``): ``rgb.txt`` and ``depth.txt`` of
``timestamp relative/path`` lines, every listed file present inside the folder, colour/depth pairs
associated like TUM's associate.py, an optional ``groundtruth.txt`` (``t tx ty tz qx qy qz qw``) and
``camera.json`` (plausible intrinsics), every frame's image headers checked (8-bit colour, 16-bit
single-channel PNG depth, one size of at least :data:`MIN_SIZE`) and a sample's whole data verified, its
depth images not all 0 (invalid).
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

from formats.association import MAX_DIFF_S, associate
from formats.errors import FormatError
from formats.trajectory import parse_tum_trajectory
from formats.tum_lists import parse_list
from storage.errors import InvalidInput
from storage.ingest.images import check_image, png_is_blank
from storage.jsonlimits import parse_json
from storage.presets import check_intrinsics

PRESET_SIZE = (640, 480)  # every camera preset (storage.presets.CAMERA_PRESETS) is 640x480
MAX_GT_POSITION_M = 1e5
"""Ground-truth positions further from the origin than this (100 km) are refused as implausible."""
MAX_LIST_BYTES = 64 * 1024 * 1024
MIN_SIZE = (64, 48)
"""Smallest image the pipeline tracks: ORB's 8-level pyramid and its 19-pixel border leave no feature in less
(32x24 frames once ran 5000 frames to a "succeeded" job that tracked none)."""


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
    try:
        listed = parse_list(_read_text(folder, path))
    except FormatError as exc:
        raise _err(folder, path, exc.message, exc.line) from None
    real_folder = folder.resolve()
    inside: dict[PurePosixPath, bool] = {}  # per listed sub-folder: does it stay inside (no symlink out)?
    for entry in listed:
        rel, lineno, shown = PurePosixPath(entry.path), entry.line, entry.path[:80]
        try:
            if rel.parent not in inside:  # a symlinked sub-folder of a registered folder may point anywhere
                inside[rel.parent] = folder.joinpath(*rel.parent.parts).resolve().is_relative_to(real_folder)
            st = os.lstat(folder.joinpath(*rel.parts))
        except (FileNotFoundError, NotADirectoryError):
            raise _err(folder, path, f"listed file {shown!r} is missing", lineno) from None
        except (OSError, RuntimeError) as exc:  # name too long, symlink loop (RuntimeError before 3.13), …
            reason = getattr(exc, "strerror", None) or "symlink loop"
            raise _err(folder, path, f"listed file {shown!r} is unusable ({reason})", lineno) from None
        if not inside[rel.parent]:
            raise _err(folder, path, f"listed file {shown!r} lies outside the sequence folder", lineno)
        if not stat.S_ISREG(st.st_mode):
            raise _err(folder, path, f"listed file {entry.path!r} is not a regular file", lineno)
    return [(e.timestamp, e.path) for e in listed]


def read_groundtruth(folder: Path) -> int:
    """Number of poses in ``groundtruth.txt`` (0 when absent); malformed lines are rejected."""
    path = folder / "groundtruth.txt"
    if not path.exists():
        return 0
    try:
        traj = parse_tum_trajectory(_read_text(folder, path))
    except FormatError as exc:
        raise _err(folder, path, exc.message, exc.line) from None
    if len(traj) and float(abs(traj.positions).max()) > MAX_GT_POSITION_M:  # evaluation's SVD diverged
        raise _err(folder, path, f"positions must lie within {MAX_GT_POSITION_M:g} m of the origin")
    return len(traj)


def read_camera_file(folder: Path) -> dict[str, Any] | None:
    path = folder / "camera.json"
    if not path.exists():
        return None
    try:
        data = parse_json(_read_text(folder, path), "camera.json")
    except InvalidInput as exc:
        raise _err(folder, path, exc.message.removeprefix("camera.json: ")) from None
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
    verified = set(picks)
    size: tuple[int, int] | None = None
    blank_depth = 0  # sampled depth images without one valid (non-zero) pixel
    for k, (i, j) in enumerate(pairs):  # every frame's headers; a sample's whole data too
        verify = k in verified
        rgb_path, depth_path = folder / rgb[i][1], folder / depth[j][1]
        c = check_image(rgb_path, verify=verify, label=rgb_path.relative_to(folder).as_posix())
        if c.bit_depth != 8 or c.color_type == 4:
            raise _err(folder, rgb_path, "colour images must be 8-bit grey, RGB or RGBA")
        d = check_image(depth_path, verify=verify, label=depth_path.relative_to(folder).as_posix())
        if d.format != "png" or d.bit_depth != 16 or d.channels != 1:
            raise _err(folder, depth_path, "depth images must be 16-bit single-channel PNG")
        if (c.width, c.height) != (d.width, d.height):
            raise _err(folder, depth_path, f"depth is {d.width}x{d.height} but colour is {c.width}x{c.height}")
        if size is not None and size != (c.width, c.height):
            raise _err(folder, rgb_path, f"image is {c.width}x{c.height} but earlier frames are {size[0]}x{size[1]}")
        if size is None and (c.width < MIN_SIZE[0] or c.height < MIN_SIZE[1]):
            raise InvalidInput(
                f"images are {c.width}x{c.height}; the pipeline needs at least {MIN_SIZE[0]}x{MIN_SIZE[1]} pixels "
                "(its ORB feature pyramid finds nothing in smaller ones)",
                {"image_size": [c.width, c.height], "min_size": list(MIN_SIZE)},
            )
        size = (c.width, c.height)
        if verify and png_is_blank(depth_path, label=depth_path.relative_to(folder).as_posix()):
            blank_depth += 1
    assert size is not None
    if blank_depth == len(verified):
        raise _err(folder, folder / "depth.txt",
                   f"every sampled depth image ({blank_depth} of {n}) is all 0, i.e. has no valid depth; "
                   "nothing can be tracked without depth (16-bit PNG, depth_scale units per metre, 0 = invalid)")
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
