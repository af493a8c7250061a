"""Pinhole RGB-D camera model and the named presets of the supported datasets."""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from formats.camera_spec import check_intrinsics
from formats.catalog import CAMERA_PRESETS, GROUNDTRUTH_FRAMES
from formats.errors import SpecError
from worker.slam.errors import CameraError


@dataclass(frozen=True)
class Camera:
    """Intrinsics of an RGB-D pair (depth normally registered to colour, see `depth_registered`).

    Depth PNG value / `depth_scale` = metres (TUM, Bonn: 5000; 7-Scenes: 1000).
    `dist` are OpenCV coefficients (k1, k2, p1, p2, k3) of the colour image.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    depth_scale: float = 5000.0
    width: int = 640
    height: int = 480
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    name: str = "custom"
    depth_registered: bool = True
    """Depth pixels lie on the colour pixels that see the same point (the driver registered them, as for TUM,
    Bonn and most RGB-D cameras); False for raw depth-camera images (7-Scenes). Sets how much keypoint depth
    weighs in pose optimisation (`tracking.virtual_baseline_m` / `unregistered_baseline_m`)."""
    groundtruth_frame: str = "camera"
    """What the sequence's ground truth is the pose of (`formats.catalog.GROUNDTRUTH_FRAMES`: `camera`, or
    `bonn-marker` for Bonn RGB-D Dynamic, corrected to the camera for RPE and the corrected ATE)."""

    def __post_init__(self) -> None:
        vals = (self.fx, self.fy, self.cx, self.cy, self.depth_scale)
        if not all(np.isfinite(v) and v > 0 for v in vals):
            raise CameraError(f"camera values must be finite and positive, got fx, fy, cx, cy, scale = {vals}")
        if self.width <= 0 or self.height <= 0:
            raise CameraError(f"camera size must be positive, got {self.width}x{self.height}")
        if len(self.dist) != 5:
            raise CameraError(f"dist needs 5 coefficients (k1 k2 p1 p2 k3), got {len(self.dist)}")
        if not isinstance(self.depth_registered, bool):
            raise CameraError(f"depth_registered must be true or false, got {self.depth_registered!r}")
        if self.groundtruth_frame not in GROUNDTRUTH_FRAMES:
            raise CameraError(f"groundtruth_frame must be one of {sorted(GROUNDTRUTH_FRAMES)}, "
                              f"got {self.groundtruth_frame!r}")

    @property
    def K(self) -> np.ndarray:
        """3x3 float64 intrinsic matrix."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    @property
    def has_distortion(self) -> bool:
        return any(abs(d) > 0 for d in self.dist)

    def scaled(self, width: int, height: int) -> Camera:
        """The same camera at another image size (e.g. a different sensor resolution)."""
        sx, sy = width / self.width, height / self.height
        return replace(self, fx=self.fx * sx, fy=self.fy * sy, cx=self.cx * sx, cy=self.cy * sy,
                       width=width, height=height)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["dist"] = list(self.dist)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Camera:
        """Explicit intrinsics checked by ``formats.camera_spec`` (the api's rules: finite, plausible, the
        principal point inside the image); 4 distortion coefficients get k3 = 0."""
        try:
            kw = check_intrinsics(d)
        except SpecError as exc:
            raise CameraError(exc.message, detail=exc.detail) from exc
        if "dist" in kw:
            kw["dist"] = tuple(kw["dist"]) + (0.0,) * (5 - len(kw["dist"]))  # k1 k2 p1 p2 without k3
        return cls(**kw)


PRESETS: dict[str, Camera] = {
    name: Camera(**asdict(c), name=name)
    for name, c in CAMERA_PRESETS.items()
}
"""The supported datasets' cameras by preset name (their intrinsics live in `formats.catalog`)."""

CAMERA_FILE = "camera.json"


def camera_from_preset(name: str) -> Camera:
    try:
        return PRESETS[name]
    except KeyError:
        raise CameraError(f"unknown camera preset {name!r}; choose one of {sorted(PRESETS)}") from None


def parse_camera(spec: str | dict) -> Camera:
    """A preset name, a JSON object string, or a dict of explicit intrinsics."""
    if isinstance(spec, dict):
        return Camera.from_dict(spec)
    text = spec.strip()
    if text.startswith("{"):
        try:
            return Camera.from_dict(json.loads(text))
        except json.JSONDecodeError as exc:
            raise CameraError(f"camera is not valid JSON: {exc}") from exc
    return camera_from_preset(text)


def load_camera_file(folder: Path) -> Camera | None:
    """The sequence's own `camera.json`, if it has one."""
    path = Path(folder) / CAMERA_FILE
    if not path.is_file():
        return None
    try:
        return Camera.from_dict(json.loads(path.read_text()))
    except json.JSONDecodeError as exc:
        raise CameraError(f"{path}: not valid JSON: {exc}") from exc
    except CameraError as exc:
        raise CameraError(f"{path}: {exc.message}") from exc
