"""Geometry: where reference pixels land in the target camera (the natural PatchMatch initialiser)."""
from __future__ import annotations

import cv2
import numpy as np
from numba import njit

from worker.slam.features.depth import backproject


def relative_pose(T_WC_ref: np.ndarray, T_WC_tgt: np.ndarray) -> np.ndarray:
    """T_tr: reference camera -> target camera (4x4)."""
    return np.linalg.inv(T_WC_tgt) @ T_WC_ref


@njit(cache=True, nogil=True)
def _splat(depth, valid, R, t, fx, fy, cx, cy, y0, y1, x0, x1, out, zbuf):
    h, w = depth.shape
    ray_x = np.empty(w)  # (x - cx) / fx once per column, not per pixel (the same arithmetic)
    for x in range(w):
        ray_x[x] = (x - cx) / fx
    for y in range(h):
        ray_y = (y - cy) / fy
        for x in range(w):
            z = depth[y, x]
            if z <= 0 or not valid[y, x]:
                continue
            X, Y = ray_x[x] * z, ray_y * z
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


def render_depth(ref_depth: np.ndarray, ref_valid: np.ndarray, T_tr: np.ndarray,
                 K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reference's `ref_valid` pixels of `ref_depth` (H, W) m seen from the target camera, whole image:
    (landed (H, W, 2) int64 as `forward_warp`, -1 where nothing lands; their depth (H, W) float32 m in the target
    camera, 0 where nothing lands)."""
    h, w = ref_depth.shape
    landed = forward_warp(ref_depth, ref_valid, T_tr, K, (0, h, 0, w))
    seen = landed[..., 0] >= 0
    depth = np.zeros((h, w), np.float32)
    depth[seen] = depth_in_target(ref_depth, landed[seen], T_tr, K)
    return landed, depth


def depth_in_target(ref_depth: np.ndarray, yx: np.ndarray, T_tr: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Depth (N,) in the target camera of reference pixels `yx` (N, 2); 0 where the reference has none."""
    z = ref_depth[yx[:, 0], yx[:, 1]].astype(np.float64)
    zt = backproject(yx[:, ::-1], z, K) @ T_tr[2, :3] + T_tr[2, 3]
    return np.where((z > 0) & (zt > 0), zt, 0.0).astype(np.float32)


def project_into_reference(target_yx: np.ndarray, z_target: np.ndarray, T_rt: np.ndarray,
                           K: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where target pixels `target_yx` (N, 2) (y, x) with depth `z_target` (N,) m land in a reference camera
    (T_rt: target camera -> reference camera): sub-pixel columns u (N,), rows v (N,) and their depth there (N,)
    m, all float64; u, v are meaningless where that depth is not positive."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    Xr = backproject(target_yx[:, ::-1], z_target, K) @ T_rt[:3, :3].T + T_rt[:3, 3]
    zr = np.maximum(Xr[:, 2], 1e-6)
    return fx * Xr[:, 0] / zr + cx, fy * Xr[:, 1] / zr + cy, Xr[:, 2]


def sample_reference(ref_rgb: np.ndarray, ref_valid: np.ndarray, target_yx: np.ndarray, z_target: np.ndarray,
                     T_tr: np.ndarray, K: np.ndarray, shift: tuple[int, int] = (0, 0)) -> tuple[np.ndarray, np.ndarray]:
    """Colours (N, 3) uint8 of target pixels `target_yx` (N, 2) with depth `z_target` (N,) m, looked up in the
    reference at the exact sub-pixel point they come from (bilinear) moved by `shift` (dy, dx) reference pixels
    (`align.ring_shift`), and a bool (N,) that is False where a bilinear neighbour is not `ref_valid` (a moving
    object's pixel must not bleed in; keep the splat's pixel).

    The splat says which reference pixel lands on a target pixel, rounded to whole pixels both ways; sampling
    back through the target pixel's centre removes that half-pixel misalignment on textured backgrounds."""
    u64, v64, z_ref = project_into_reference(target_yx, z_target, np.linalg.inv(T_tr), K)
    u = (u64 + shift[1]).astype(np.float32)
    v = (v64 + shift[0]).astype(np.float32)
    n, cols = len(u), 1024  # remap wants maps under 32767 wide: sample the N points as a (rows, 1024) image
    rows = max(1, -(-n // cols))
    pad = rows * cols - n
    rgb = cv2.remap(ref_rgb, np.pad(u, (0, pad)).reshape(rows, cols), np.pad(v, (0, pad)).reshape(rows, cols),
                    cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(-1, 3)[:n]
    h, w = ref_valid.shape
    x0, y0 = np.floor(u).astype(int), np.floor(v).astype(int)
    ok = (z_ref > 1e-3) & (x0 >= 0) & (y0 >= 0) & (x0 + 1 < w) & (y0 + 1 < h)
    xs, ys = np.clip(x0, 0, w - 2), np.clip(y0, 0, h - 2)
    ok &= ref_valid[ys, xs] & ref_valid[ys, xs + 1] & ref_valid[ys + 1, xs] & ref_valid[ys + 1, xs + 1]
    return rgb, ok
