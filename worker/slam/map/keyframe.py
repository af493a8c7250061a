"""Keyframes: a frame kept in the map with its features, the map points they observe and a small RGB-D copy."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from worker.slam.features.types import Features


@dataclass
class KeyFrame:
    """`T_WC` 4x4 float64 (updated by BA / loop closure). `point_ids` (N,) int64 map point per keypoint
    (-1 none). `rgb_small` (h,w,3) uint8 RGB and `depth_small` (h,w) float32 metres (0 = invalid or excluded)
    are the strided copy the dense map is fused from; `measured_small` (h,w) float32 metres is the same
    pixels' raw sensor depth, excluded regions included: where it lies behind a map point, that point was
    not there when this keyframe looked (the map's carving)."""

    id: int
    frame_index: int
    timestamp: float
    T_WC: np.ndarray
    feats: Features
    point_ids: np.ndarray
    rgb_small: np.ndarray | None = None
    depth_small: np.ndarray | None = None
    measured_small: np.ndarray | None = None
    bow: dict[int, float] = field(default_factory=dict)

    def set_dense_images(self, rgb: np.ndarray, depth: np.ndarray, stride: int) -> None:
        """Replace the copy the dense map is fused from with every `stride`-th pixel of `rgb` (H,W,3) uint8 RGB
        and `depth` (H,W) float32 m, as the tracker takes them (a frame restored after it became a keyframe)."""
        self.rgb_small = rgb[::stride, ::stride].copy()
        self.depth_small = np.ascontiguousarray(depth[::stride, ::stride]).copy()

    @property
    def center(self) -> np.ndarray:
        return self.T_WC[:3, 3]
