"""Dense map: keyframes' (static, restored) RGB-D back-projected with their final poses, voxel-filtered."""
from __future__ import annotations

import numpy as np

from worker.slam.map.keyframe import KeyFrame


def pixel_rays(K: np.ndarray, dist: np.ndarray | None, shape: tuple[int, int], stride: int) -> np.ndarray:
    """(h,w,2) normalised image coordinates (x/z, y/z) of the strided pixel grid, undistorted if `dist`."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float64) * stride
    if dist is None or not np.any(dist):
        return np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]], -1)
    import cv2

    pts = np.stack([u, v], -1).reshape(-1, 1, 2)
    return cv2.undistortPoints(pts, K, np.asarray(dist, np.float64)).reshape(h, w, 2)


def depth_edges(d: np.ndarray, rel: float) -> np.ndarray:
    """bool (h,w): pixels whose 3x3 neighbourhood spans more than `rel` x depth, or touches a hole.

    Depth sensors interpolate across silhouettes ("flying pixels" floating between foreground and
    background); fusing them would put a veil in front of every edge.
    """
    import cv2

    k = np.ones((3, 3), np.uint8)
    near_hole = cv2.erode((d > 0).astype(np.uint8), k) == 0
    lo = cv2.erode(np.where(d > 0, d, 1e6).astype(np.float32), k)
    hi = cv2.dilate(d.astype(np.float32), k)
    return near_hole | (hi - lo > rel * lo)


def backproject_keyframe(kf: KeyFrame, K: np.ndarray, stride: int, max_depth: float,
                         rays: np.ndarray | None = None, edge_rel: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """World points (N,3) float64 and colours (N,3) uint8 of a keyframe's strided RGB-D copy.

    `rays` (h,w,2) normalised coordinates of the grid (see `pixel_rays`); pinhole without distortion if None.
    Pixels at depth edges (relative jump > `edge_rel` in the 3x3 neighbourhood; 0 = keep all) are dropped.
    """
    d, rgb = kf.depth_small, kf.rgb_small
    assert d is not None and rgb is not None, "only keyframes that kept their RGB-D copy are back-projected"
    if rays is None:
        rays = pixel_rays(K, None, d.shape, stride)
    ok = (d > 0) & (d < max_depth)
    if edge_rel > 0:
        ok &= ~depth_edges(d, edge_rel)
    z = d[ok].astype(np.float64)
    x = rays[..., 0][ok] * z
    y = rays[..., 1][ok] * z
    Xc = np.column_stack([x, y, z])
    Xw = Xc @ kf.T_WC[:3, :3].T + kf.T_WC[:3, 3]
    return Xw, rgb[ok]


def voxel_filter(xyz: np.ndarray, rgb: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Average points and colours per voxel: (M,3) float32 and (M,3) uint8."""
    if len(xyz) == 0:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)
    keys = np.floor(xyz / voxel).astype(np.int64)
    keys -= keys.min(0)
    span = keys.max(0) + 1
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, inv, counts = np.unique(flat, return_inverse=True, return_counts=True)
    out = np.zeros((len(counts), 3))
    col = np.zeros((len(counts), 3))
    np.add.at(out, inv, xyz)
    np.add.at(col, inv, rgb.astype(np.float64))
    return (out / counts[:, None]).astype(np.float32), np.clip(col / counts[:, None] + 0.5, 0, 255).astype(np.uint8)


def fuse_keyframes(keyframes: list[KeyFrame], K: np.ndarray, stride: int, voxel: float, max_depth: float,
                   dist: np.ndarray | None = None, edge_rel: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Coloured point cloud of all keyframes, voxel-filtered incrementally so memory stays bounded.

    `dist` OpenCV distortion coefficients of the images (depth registered to colour), None = pinhole.
    """
    xyz, rgb = np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)
    batch_x, batch_c, n = [], [], 0
    rays = None
    for kf in keyframes:
        if kf.depth_small is None:
            continue
        if rays is None or rays.shape[:2] != kf.depth_small.shape:
            rays = pixel_rays(K, dist, kf.depth_small.shape, stride)
        x, c = backproject_keyframe(kf, K, stride, max_depth, rays, edge_rel)
        batch_x.append(x)
        batch_c.append(c)
        n += len(x)
        if n > 2_000_000:
            xyz, rgb = voxel_filter(np.vstack([xyz] + batch_x), np.vstack([rgb] + batch_c), voxel)
            batch_x, batch_c, n = [], [], 0
    if batch_x:
        xyz, rgb = voxel_filter(np.vstack([xyz] + batch_x), np.vstack([rgb] + batch_c), voxel)
    return xyz, rgb
