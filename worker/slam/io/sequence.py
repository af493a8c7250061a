"""A TUM-layout RGB-D sequence folder (also Bonn, and 7-Scenes with TUM-style lists), read lazily."""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from formats.association import MAX_DIFF_S, associate
from formats.errors import FormatError
from formats.tum_lists import read_list
from worker.slam.camera import Camera, load_camera_file
from worker.slam.errors import CameraError, SequenceFormatError, TrajectoryFormatError
from worker.slam.io.images import read_depth, read_rgb
from worker.slam.io.trajectory import Trajectory, read_tum_trajectory


@dataclass(frozen=True)
class Frame:
    """One associated RGB-D frame. `rgb` RGB uint8 (H, W, 3); `depth` float32 metres (H, W), 0 = invalid."""

    index: int
    timestamp: float
    rgb: np.ndarray
    depth: np.ndarray


@dataclass(frozen=True)
class FrameRef:
    """Where a frame lives on disk, before it is read."""

    timestamp: float
    rgb_path: Path
    depth_path: Path


class Sequence:
    """Associated frames of a sequence folder. Frames are decoded only when indexed or iterated."""

    def __init__(self, root: Path | str, camera: Camera | None = None, max_diff: float = MAX_DIFF_S) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise SequenceFormatError("sequence folder not found", path=self.root)
        own = load_camera_file(self.root)
        if camera is None and own is None:
            raise CameraError(f"{self.root}: no camera given and no camera.json in the folder")
        #: The sequence's own camera.json wins over a preset: it describes these very images.
        self.camera: Camera = own or camera  # type: ignore[assignment]
        self.camera_source = "camera.json" if own else "given"
        try:
            rgb = read_list(self.root / "rgb.txt")
            depth = read_list(self.root / "depth.txt")
        except FormatError as exc:
            raise SequenceFormatError(exc.message, path=exc.path, line=exc.line) from None
        pairs = associate([e.timestamp for e in rgb], [e.timestamp for e in depth], max_diff)
        if not pairs:
            raise SequenceFormatError(f"no rgb/depth pairs within {max_diff} s", path=self.root / "rgb.txt")
        self.frames: list[FrameRef] = [
            FrameRef(rgb[i].timestamp, self.root / rgb[i].path, self.root / depth[j].path) for i, j in pairs
        ]
        self.n_rgb, self.n_depth = len(rgb), len(depth)
        gt_path = self.root / "groundtruth.txt"
        try:
            self.groundtruth: Trajectory | None = read_tum_trajectory(gt_path) if gt_path.is_file() else None
        except TrajectoryFormatError as exc:
            raise SequenceFormatError(exc.message) from exc

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def timestamps(self) -> np.ndarray:
        return np.array([f.timestamp for f in self.frames])

    @property
    def duration(self) -> float:
        return self.frames[-1].timestamp - self.frames[0].timestamp

    def __getitem__(self, index: int) -> Frame:
        if not -len(self) <= index < len(self):
            raise IndexError(index)
        index %= len(self)
        ref = self.frames[index]
        rgb = read_rgb(ref.rgb_path)
        depth = read_depth(ref.depth_path, self.camera.depth_scale)
        if rgb.shape[:2] != depth.shape:
            raise SequenceFormatError(f"colour {rgb.shape[1]}x{rgb.shape[0]} and depth "
                                      f"{depth.shape[1]}x{depth.shape[0]} sizes differ", path=ref.depth_path)
        h, w = depth.shape
        if (w, h) != (self.camera.width, self.camera.height):
            if abs(w / h - self.camera.width / self.camera.height) > 1e-3:
                raise SequenceFormatError(f"image is {w}x{h} but camera {self.camera.name} is "
                                          f"{self.camera.width}x{self.camera.height}", path=ref.rgb_path)
            self.camera = self.camera.scaled(w, h)
        return Frame(index, ref.timestamp, rgb, depth)

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    def groundtruth_for_frames(self, max_diff: float = MAX_DIFF_S) -> tuple[np.ndarray, np.ndarray]:
        """(frame indices, (M,4,4) T_WC) for the frames that have a GT pose within `max_diff`."""
        if self.groundtruth is None:
            return np.zeros(0, dtype=int), np.zeros((0, 4, 4))
        pairs = associate(self.timestamps, self.groundtruth.timestamps, max_diff)
        idx = np.array([i for i, _ in pairs], dtype=int)
        poses = self.groundtruth.poses[[j for _, j in pairs]] if pairs else np.zeros((0, 4, 4))
        return idx, poses


def open_sequence(root: Path | str, camera: Camera | None = None) -> Sequence:
    return Sequence(root, camera)
