"""Geometry: where reference pixels land in the target camera (the natural PatchMatch initialiser)."""
from __future__ import annotations

import numpy as np
from numba import njit


def relative_pose(T_WC_ref: np.ndarray, T_WC_tgt: np.ndarray) -> np.ndarray:
    """T_tr: reference camera -> target camera (4x4)."""
    return np.linalg.inv(T_WC_tgt) @ T_WC_ref


@njit(cache=True)
def _splat(depth, valid, R, t, fx, fy, cx, cy, y0, y1, x0, x1, out, zbuf):
    h, w = depth.shape
    for y in range(h):
        for x in range(w):
            z = depth[y, x]
            if z <= 0 or not valid[y, x]:
                continue
            X, Y = (x - cx) / fx * z, (y - cy) / fy * z
            zt = R[2, 0] * X + R[2, 1] * Y + R[2, 2] * z + t[2]
            if zt <= 1e-3:
                continue
            u = int(np.floor((R[0, 0] * X + R[0, 1] * Y + R[0, 2] * z + t[0]) / zt * fx + cx + 0.5))
            v = int(np.floor((R[1, 0] * X + R[1, 1] * Y + R[1, 2] * z + t[1]) / zt * fy + cy + 0.5))
            if u < x0 or u >= x1 or v < y0 or v >= y1:
                continue
            if zt < zbuf[v - y0, u - x0]:  # z-buffer: the nearest point wins, as in a real image
                zbuf[v - y0, u - x0] = zt
                out[v - y0, u - x0, 0] = y
                out[v - y0, u - x0, 1] = x


def forward_warp(ref_depth: np.ndarray, ref_valid: np.ndarray, T_tr: np.ndarray, K: np.ndarray,
                 region: tuple[int, int, int, int]) -> np.ndarray:
    """For target pixels in `region` (y0, y1, x0, x1), the reference pixel (y, x) that lands there, else -1.

    `ref_depth` float32 m (H, W); `ref_valid` bool (H, W) marks pixels that may be copied (static).
    Returns (y1 - y0, x1 - x0, 2) int64.
    """
    y0, y1, x0, x1 = region
    out = np.full((y1 - y0, x1 - x0, 2), -1, np.int64)
    zbuf = np.full((y1 - y0, x1 - x0), np.inf, np.float64)
    _splat(np.ascontiguousarray(ref_depth, np.float32), np.ascontiguousarray(ref_valid, np.bool_),
           np.ascontiguousarray(T_tr[:3, :3]), np.ascontiguousarray(T_tr[:3, 3]),
           float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), y0, y1, x0, x1, out, zbuf)
    return out


def depth_in_target(ref_depth: np.ndarray, yx: np.ndarray, T_tr: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Depth (N,) in the target camera of reference pixels `yx` (N, 2); 0 where the reference has none."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    z = ref_depth[yx[:, 0], yx[:, 1]].astype(np.float64)
    X = np.stack([(yx[:, 1] - cx) / fx * z, (yx[:, 0] - cy) / fy * z, z], axis=1)
    zt = X @ T_tr[2, :3] + T_tr[2, 3]
    return np.where((z > 0) & (zt > 0), zt, 0.0).astype(np.float32)
