"""The names the api and the pipeline agree on: pipeline presets and camera presets, as plain data.

The api validates a job's preset and a sequence's camera against these names without importing the
pipeline; the pipeline builds its `PipelineConfig`s (worker.slam.presets) and `Camera`s (worker.slam.camera)
from the same entries, so there is one list to edit.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PipelinePreset:
    name: str
    description: str
    stages: tuple[str, ...]
    """Per-frame stages run before tracking, in order (names registered by worker.slam.presets)."""


PIPELINE_PRESETS: tuple[PipelinePreset, ...] = (
    PipelinePreset("full", "VTD-SLAM: MSNET segmentation + adaptive epipolar culling + background restoration "
                   "from reference frames", ("segmentation", "culling", "restoration")),
    PipelinePreset("no-restoration", "MSNET segmentation + adaptive epipolar culling, no background restoration",
                   ("segmentation", "culling")),
    PipelinePreset("geometry-only", "epipolar/depth culling of moving clusters, no segmentation, no restoration",
                   ("culling",)),
    PipelinePreset("orb-only", "ORB-SLAM2-style RGB-D tracking and mapping, no dynamic handling", ()),
)
"""Most complete first."""

DEFAULT_PIPELINE_PRESET = "full"
"""What a run or job uses when it names no preset."""


@dataclass(frozen=True)
class CameraPreset:
    """Pinhole intrinsics of a dataset's RGB-D pair; depth PNG value / `depth_scale` = metres."""

    fx: float
    fy: float
    cx: float
    cy: float
    depth_scale: float
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    """OpenCV coefficients (k1, k2, p1, p2, k3) of the colour image."""
    width: int = 640
    height: int = 480
    depth_registered: bool = True
    """Depth pixels are registered to the colour pixels (the driver reprojected them: TUM, Bonn); False when the
    dataset ships the depth camera's own images (7-Scenes)."""


CAMERA_PRESETS: dict[str, CameraPreset] = {
    # TUM RGB-D (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats): ROS-default registered depth.
    "tum1": CameraPreset(517.3, 516.5, 318.6, 255.3, 5000.0, dist=(0.2624, -0.9531, -0.0054, 0.0026, 1.1633)),
    "tum2": CameraPreset(520.9, 521.0, 325.1, 249.7, 5000.0, dist=(0.2312, -0.7849, -0.0033, -0.0001, 0.9172)),
    "tum3": CameraPreset(535.4, 539.2, 320.1, 247.6, 5000.0),
    # Bonn RGB-D Dynamic (its documented intrinsics; k3 not given).
    "bonn": CameraPreset(542.822841, 542.576870, 315.593520, 237.756098, 5000.0,
                         dist=(0.039903, -0.099343, -0.000730, -0.000144, 0.0)),
    # Microsoft 7-Scenes nominal depth intrinsics; depth in millimetres, from the Kinect's depth camera and not
    # registered to colour (the dataset says so): a keypoint's depth may be a neighbouring surface's.
    "7scenes": CameraPreset(585.0, 585.0, 320.0, 240.0, 1000.0, depth_registered=False),
}
