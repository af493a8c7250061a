"""The two frames culling compares: the previous frame's keypoints and depth, the current frame's, and what
the tracker predicts between them."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def nearest_pixel(coord: np.ndarray, size: int) -> np.ndarray:
    """int (N,): the nearest pixel index of each coordinate (N,) px, clipped to an axis of `size` pixels."""
    return np.clip(np.round(coord).astype(int), 0, size - 1)


@dataclass(frozen=True)
class FramePair:
    """What culling reads of a previous and a current frame.

    Keypoints are in the raw image, where masks and depth live: `*_uv` (N, 2) float px (x, y), `*_desc`
    (N, 32) uint8 ORB descriptors. Depth maps are float32 (H, W) m, 0 = none. Poses and K are float64.
    """

    prev_uv: np.ndarray
    prev_desc: np.ndarray
    cur_uv: np.ndarray
    cur_desc: np.ndarray
    cur_depth: np.ndarray
    potentially_dynamic: np.ndarray | None
    """bool (H, W) from segmentation; None without (geometry-only)."""
    pose_cov: np.ndarray | None
    """6x6 covariance of the previous pose estimate (for Δd); None = unknown."""
    prev_depth: np.ndarray | None = None
    """With `K`, enables the reprojection test (and, with `T_cur_prev`, guided matching)."""
    K: np.ndarray | None = None
    """3x3 intrinsics of both frames."""
    T_cur_prev: np.ndarray | None = None
    """4x4 predicted relative pose (X_cur = T X_prev, camera frames) from the tracker; None = no prediction."""

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the current frame."""
        h, w = self.cur_depth.shape
        return h, w

    def prev_depth_at(self, uv: np.ndarray) -> np.ndarray:
        """float32 (N,) m: the previous depth at the nearest pixel of each previous-frame point (N, 2) px (x, y).
        Only with `prev_depth`."""
        assert self.prev_depth is not None
        h, w = self.prev_depth.shape
        return self.prev_depth[nearest_pixel(uv[:, 1], h), nearest_pixel(uv[:, 0], w)]
