"""Free-space carving of the dense map: drop points that the keyframes' measured depth sees through.

Why: segmentation misses parts of people (and anything else that moves), and a missed piece enters the map
at the moment it was seen. Every other view that looks at the same place *before it came or after it left*
measures the static surface behind it, i.e. free space where the map has a point. A static surface is never
seen through (only occluded, which is a measurement in front of it), so a point that a few views saw through
was a passer-by, however often others saw it: a person who lingers is seen by many views and seen through
only by those before or after. The raw sensor depth is used, masked regions included: a mask says "something
that may move is here", never "the space in front of it is not free".

The views that vote are every n-th tracked frame at its final pose (`FrameViews`), or the keyframes: a person
pasted or standing where few keyframes look behind it is seen through by the frames in between.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from worker.slam.map.keyframe import KeyFrame

View = tuple[np.ndarray, np.ndarray]
"""A view that votes: its 4x4 T_WC and its measured depth (h, w) float32 metres at the dense stride."""


@dataclass
class FrameViews:
    """Every `every`-th frame's measured depth at `stride`, by its position in the run, kept for carving once
    the final poses are known. Past `max_views` every other one is dropped and `every` doubles, so a long run
    holds at most `max_views` images (77 kB each at 640x480 and stride 4)."""

    every: int
    stride: int
    max_views: int
    depth: dict[int, np.ndarray] = field(default_factory=dict)

    def offer(self, k: int, measured: np.ndarray) -> None:
        """Frame `k` of the run with its measured depth (H, W) float32 metres."""
        if self.every <= 0 or k % self.every:
            return
        self.depth[k] = np.array(measured[::self.stride, ::self.stride], dtype=np.float32, order="C")  # own copy
        if len(self.depth) > self.max_views:
            self.every *= 2
            self.depth = {i: d for i, d in self.depth.items() if i % self.every == 0}

    def views(self, poses: np.ndarray, tracked: np.ndarray) -> list[View]:
        """The kept frames that were tracked, at their final `poses` (N,4,4) T_WC by position in the run."""
        return [(poses[k], d) for k, d in sorted(self.depth.items()) if tracked[k]]


def keyframe_views(keyframes: list[KeyFrame]) -> list[View]:
    """The keyframes as views (those that keep their measured depth)."""
    return [(kf.T_WC, kf.measured_small) for kf in keyframes if kf.measured_small is not None]


def visibility_votes(xyz_t: np.ndarray, view: View, K_small: np.ndarray, rel_tol: float,
                     min_tol_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices into `xyz_t` (3,M) float32 world points (one row per axis: whole-row arithmetic is several
    times faster than an (M,3) matmul here) twice: the points this view saw through (its measured depth
    lies behind the point by more than the tolerance at every pixel of the 3x3 neighbourhood), and the points
    it saw (depth within the tolerance). The tolerance is `max(min_tol_m, rel_tol * depth)`; the
    neighbourhood keeps points on silhouettes from counting as seen through when a pose is off by a pixel."""
    T_WC, measured = view
    h, w = measured.shape
    R = T_WC[:3, :3].astype(np.float32)
    o = T_WC[:3, 3].astype(np.float32) @ R  # camera coordinates are R^T (X - t) = R^T X - R^T t

    def axis(k: int) -> np.ndarray:
        return R[0, k] * xyz_t[0] + R[1, k] * xyz_t[1] + R[2, k] * xyz_t[2] - o[k]

    z = axis(2)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = K_small[0, 0] * axis(0) / z + K_small[0, 2]
        v = K_small[1, 1] * axis(1) / z + K_small[1, 2]
    idx = np.flatnonzero((z > 0.1) & (u >= -0.5) & (u < w - 0.5) & (v >= -0.5) & (v < h - 0.5))
    ui = (u[idx] + 0.5).astype(np.intp)  # nearest pixel (all values are >= -0.5 here)
    vi = (v[idx] + 0.5).astype(np.intp)
    zi = z[idx]
    nearest = cv2.erode(np.where(measured > 0, measured, np.float32(1e6)).astype(np.float32), np.ones((3, 3), np.uint8))
    tol = np.maximum(min_tol_m, rel_tol * zi)
    d_near = nearest[vi, ui]
    d = measured[vi, ui]
    through = (d_near < 1e5) & (d_near > zi + tol)
    seen = (d > 0) & (np.abs(d - zi) <= tol)
    return idx[through], idx[seen]


def carve(xyz: np.ndarray, rgb: np.ndarray, views: list[View], K: np.ndarray, stride: int,
          rel_tol: float = 0.03, min_tol_m: float = 0.05, min_through: int = 3,
          majority: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The map `xyz` (M,3) float32 world points with colours `rgb` (M,3) uint8, less the points that at least
    `min_through` views saw through (`majority`: and that were seen through more often than seen, the earlier
    rule, which kept a person who stayed in view for more keyframes than saw the place free).
    `K` 3x3 full-image intrinsics; each view's depth holds every `stride`-th pixel (pinhole: distortion is
    below the tolerance at this stride)."""
    if not views or len(xyz) == 0:
        return xyz, rgb
    K_small = K.astype(np.float64).copy()
    K_small[:2] /= stride
    X_t = np.ascontiguousarray(xyz.T, dtype=np.float32)
    n_through = np.zeros(len(xyz), np.int32)
    n_seen = np.zeros(len(xyz), np.int32)
    for view in views:
        through, seen = visibility_votes(X_t, view, K_small, rel_tol, min_tol_m)
        n_through[through] += 1  # indices are unique per view
        n_seen[seen] += 1
    carved = n_through >= min_through
    if majority:
        carved &= n_through > n_seen
    keep = ~carved
    return xyz[keep], rgb[keep]
