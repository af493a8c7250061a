"""Depth at keypoints and back-projection to camera coordinates."""
from __future__ import annotations

import numpy as np


def lookup_depth(uv: np.ndarray, depth: np.ndarray, min_m: float, max_m: float,
                 max_rel_step: float = 0.03, edge_radius: int = 0) -> np.ndarray:
    """(N,) float32 depth at each (N,2) subpixel `uv`; 0 where invalid or outside [min_m, max_m].

    `depth` is float32 metres (H, W), 0 = invalid. Bilinear where the 2x2 neighbourhood is valid and smooth
    (relative spread below `max_rel_step`), so slanted surfaces get sub-pixel-accurate depth; the nearest
    pixel otherwise, because interpolating across a depth edge invents points between two surfaces.
    `edge_radius` > 0: keypoints with a depth edge (or a hole) within that many pixels get no depth at all,
    for sensors whose depth is not exactly registered to colour (the depth of a silhouette corner is then
    a guess between foreground and background).
    """
    h, w = depth.shape
    if len(uv) == 0:
        return np.zeros(0, np.float32)
    x = np.clip(uv[:, 0], 0, w - 1.001)
    y = np.clip(uv[:, 1], 0, h - 1.001)
    x0, y0 = x.astype(int), y.astype(int)
    fx, fy = x - x0, y - y0
    d00, d01 = depth[y0, x0], depth[y0, x0 + 1]
    d10, d11 = depth[y0 + 1, x0], depth[y0 + 1, x0 + 1]
    quad = np.stack([d00, d01, d10, d11], 1)
    lo, hi = quad.min(1), quad.max(1)
    smooth = (lo > 0) & (hi - lo < max_rel_step * np.maximum(lo, 1e-6))
    bil = (d00 * (1 - fx) * (1 - fy) + d01 * fx * (1 - fy) + d10 * (1 - fx) * fy + d11 * fx * fy)
    near = depth[np.clip(np.rint(uv[:, 1]).astype(int), 0, h - 1), np.clip(np.rint(uv[:, 0]).astype(int), 0, w - 1)]
    z = np.where(smooth, bil, near).astype(np.float32)
    z[(z < min_m) | (z > max_m) | ~np.isfinite(z)] = 0.0
    if edge_radius > 0:
        r = np.arange(-edge_radius, edge_radius + 1)
        uu = np.clip(np.rint(uv[:, 0]).astype(int)[:, None, None] + r[None, None, :], 0, w - 1)
        vv = np.clip(np.rint(uv[:, 1]).astype(int)[:, None, None] + r[None, :, None], 0, h - 1)
        win = depth[vv, uu].reshape(len(uv), -1)
        lo, hi = win.min(1), win.max(1)
        z[(lo <= 0) | (hi - lo > 4 * max_rel_step * np.maximum(lo, 1e-6))] = 0.0
    return z


def depth_weights(uv: np.ndarray, z: np.ndarray, depth: np.ndarray, bf: float, k_per_m2: float,
                  radius: int = 2) -> np.ndarray:
    """(N,) float32 weight of each keypoint's depth residual relative to the virtual baseline's (u_r row scale).

    The u_r = u - bf/z residual with a 1-pixel sigma stands for a depth sigma of z^2/bf, the same for every
    keypoint. Here each keypoint gets its own depth sigma from the image: the sensor's z-squared law k*z^2
    (structured light) combined with half the depth range in a (2r+1)^2 window around its raw pixel `uv` (N,2),
    which is large at depth edges, mixed pixels and steep slopes (where a pixel's error in position is one in
    depth) and small on flat surfaces; a hole in the window counts as a range of z. Weight = (z^2/bf) / sigma.
    `z` (N,) the keypoints' depth (0 = none: weight 1, unused); `depth` (H,W) float32 metres, 0 = invalid.
    """
    w = np.ones(len(uv), np.float32)
    has = z > 0
    if not has.any():
        return w
    h, wd = depth.shape
    r = np.arange(-radius, radius + 1)
    uu = np.clip(np.rint(uv[has, 0]).astype(int)[:, None, None] + r[None, None, :], 0, wd - 1)
    vv = np.clip(np.rint(uv[has, 1]).astype(int)[:, None, None] + r[None, :, None], 0, h - 1)
    win = depth[vv, uu].reshape(int(has.sum()), -1)
    zk = z[has].astype(np.float64)
    hole = (win <= 0).any(1)
    spread = np.where(hole, zk, 0.5 * (win.max(1) - np.where(win > 0, win, np.inf).min(1)))
    sigma = np.sqrt((k_per_m2 * zk**2) ** 2 + spread**2)
    w[has] = zk**2 / (bf * np.maximum(sigma, 1e-9))
    return w


def backproject(uv: np.ndarray, z: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N,3) camera-frame points from (N,2) pixels `uv` and (N,) depths `z` (metres, along the optical axis)."""
    x = (uv[:, 0] - K[0, 2]) / K[0, 0] * z
    y = (uv[:, 1] - K[1, 2]) / K[1, 1] * z
    return np.stack([x, y, z], axis=1).astype(np.float64)
