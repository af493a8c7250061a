"""What `vtdslam stream` sends: a TUM-layout folder's associated frames (a ROS bag is imported to one first,
by `storage.ingest.bag`), with its camera.json and ground truth when it has them."""
from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from formats.association import associate
from formats.tum_lists import read_list
from storage.errors import InvalidInput


@dataclass(frozen=True)
class StreamSource:
    """Frames (timestamp s, colour file, depth file) in time order; the folder's camera.json and ground truth."""

    frames: list[tuple[float, Path, Path]]
    camera: dict[str, Any] | None
    groundtruth: str | None


def tum_source(folder: Path, max_frames: int | None = None) -> StreamSource:
    """The associated colour/depth pairs of a TUM-layout folder (at most `max_frames`)."""
    if not (folder / "rgb.txt").is_file() or not (folder / "depth.txt").is_file():
        raise InvalidInput(f"{folder}: not a TUM-layout folder (rgb.txt and depth.txt)")
    rgb, depth = read_list(folder / "rgb.txt"), read_list(folder / "depth.txt")
    pairs = associate([e.timestamp for e in rgb], [e.timestamp for e in depth])
    frames = [(rgb[i].timestamp, folder / rgb[i].path, folder / depth[j].path) for i, j in pairs][:max_frames]
    if not frames:
        raise InvalidInput(f"{folder}: no colour/depth pairs")
    cam = folder / "camera.json"
    gt = folder / "groundtruth.txt"
    return StreamSource(frames, json.loads(cam.read_text()) if cam.is_file() else None,
                        gt.read_text(encoding="utf-8") if gt.is_file() else None)


@contextmanager
def open_source(path: Path, scratch: Path, max_frames: int | None = None) -> Iterator[StreamSource]:
    """A TUM folder as it is; a ROS 1/2 bag (file or ROS 2 folder) imported into `scratch` first."""
    from storage.ingest.bag import find_bag_folder, import_bag, sniff_bag

    if path.is_file() and sniff_bag(path) is None:
        raise InvalidInput(f"{path}: neither a TUM-layout folder nor a ROS bag")
    if path.is_file() or (path.is_dir() and not (path / "rgb.txt").is_file() and find_bag_folder(path)):
        out = scratch / "sequence"
        import_bag(path, out)
        yield tum_source(out, max_frames)
        return
    yield tum_source(path, max_frames)
