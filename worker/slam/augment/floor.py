"""The floor plane of a real RGB-D sequence in its ground-truth world frame, so inserted people stand on it.

The world frame of 7-Scenes-like data is arbitrary (KinectFusion's), so "up" is estimated first as the common
normal of the horizontal surfaces seen (starting from the cameras' mean image-up), then the floor is the lowest
well-supported height along it (a histogram of back-projected depth samples).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.camera import Camera


@dataclass(frozen=True)
class Floor:
    """Plane `up . p = height` in the world; `up` (3,) unit vector pointing away from the floor."""

    up: np.ndarray
    height: float
    inliers: int

    def project(self, p: np.ndarray) -> np.ndarray:
        """(..., 3) world points dropped vertically onto the floor."""
        return p - ((p @ self.up) - self.height)[..., None] * self.up


def backproject(depth: np.ndarray, camera: Camera, T_WC: np.ndarray, step: int = 8) -> np.ndarray:
    """(N, 3) world points from a float32 (H, W) depth map, every `step`-th pixel, valid depth only."""
    d = depth[::step, ::step]
    v, u = np.nonzero(d > 0)
    z = d[v, u].astype(np.float64)
    pc = np.stack([(u * step - camera.cx) / camera.fx * z, (v * step - camera.cy) / camera.fy * z, z], axis=1)
    return pc @ T_WC[:3, :3].T + T_WC[:3, 3]


def world_normals(depth: np.ndarray, camera: Camera, T_WC: np.ndarray, step: int = 4) -> np.ndarray:
    """(N, 3) unit surface normals (world frame, facing the camera) from a float32 (H, W) depth map, sampled
    every `step` pixels, from central differences of the back-projected points."""
    d = depth[::step, ::step].astype(np.float64)
    h, w = d.shape
    v, u = np.mgrid[0:h, 0:w] * step
    P = np.stack([(u - camera.cx) / camera.fx * d, (v - camera.cy) / camera.fy * d, d], axis=-1)
    du = P[1:-1, 2:] - P[1:-1, :-2]
    dv = P[2:, 1:-1] - P[:-2, 1:-1]
    n = np.cross(du, dv)
    valid = (d[1:-1, 2:] > 0) & (d[1:-1, :-2] > 0) & (d[2:, 1:-1] > 0) & (d[:-2, 1:-1] > 0)
    # Reject normals across depth jumps: neighbours must be within 5 % of the centre's depth.
    centre = d[1:-1, 1:-1]
    smooth = (np.abs(d[1:-1, 2:] - d[1:-1, :-2]) < 0.05 * centre) & (np.abs(d[2:, 1:-1] - d[:-2, 1:-1]) < 0.05 * centre)
    n = n[valid & smooth]
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return -(n @ T_WC[:3, :3].T)  # du x dv points away from the camera for y-down images


def gravity_up(poses: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
    """World up (3,) from camera poses T_WC (M, 4, 4) and world surface normals (N, 3).

    The cameras' mean image-up (-y) is only a rough guess (a camera looking down at a table tilts it), so the
    estimate is refined to the dominant normal of the near-horizontal surfaces (floor, tables, counters all
    share it) by a shrinking-window mean shift."""
    up = -poses[:, :3, 1].mean(axis=0)
    up /= np.linalg.norm(up)
    if normals is None or len(normals) < 100:
        return up
    for window_deg in (40.0, 20.0, 10.0, 5.0, 5.0):
        sel = normals[normals @ up > np.cos(np.radians(window_deg))]
        if len(sel) < 50:
            break
        up = sel.mean(axis=0)
        up /= np.linalg.norm(up)
    return up


def estimate_floor(points: np.ndarray, poses: np.ndarray, up: np.ndarray, bin_m: float = 0.02,
                   min_support: float = 0.01, fallback_below_camera: float = 1.4) -> Floor:
    """Floor from world `points` (N, 3), camera poses T_WC (M, 4, 4) and world `up` (3,): along up, the
    lowest height bin holding at least `min_support` of the points, moved to the top of its peak and refined
    by the median of the points within one bin of it (a table top holds more points, but is higher).
    Falls back to `fallback_below_camera` m below the mean camera when the floor is never seen."""
    fallback = Floor(up, float((poses[:, :3, 3] @ up).mean() - fallback_below_camera), 0)
    if len(points) < 100:
        return fallback
    h = points @ up
    lo = np.percentile(h, 0.1)  # ignore the odd outlier below the floor
    edges = np.arange(lo, np.percentile(h, 99.9) + bin_m, bin_m)
    counts = np.convolve(np.histogram(h, bins=edges)[0], np.ones(3), mode="same")
    above = np.nonzero(counts >= max(50, min_support * len(h)))[0]
    if len(above) == 0:
        return fallback
    first = above[0]
    peak = first + int(np.argmax(counts[first:first + 6]))  # climb to the top of that peak (<= 10 cm)
    centre = (edges[peak] + edges[peak + 1]) / 2
    near = np.abs(h - centre) < 1.5 * bin_m
    return Floor(up, float(np.median(h[near])), int(near.sum()))
