"""Future frames as restoration references (both-sided mode): their pose and moving pixels, from geometry alone.

A job has the whole sequence, so frames after the target can show background the past never did. Those frames
are not tracked yet and not segmented yet, so both are estimated against the target:

* pose: the target's keypoints with depth (3D, outside the hole) matched to the future frame's ORB keypoints,
  PnP-RANSAC -> T_WC of the future frame relative to the target's predicted pose (moving keypoints are RANSAC
  outliers);
* moving pixels: a future pixel whose 3D point lands in front of what the target sees there (static
  background seen through it, or in front of / at the target's own occluder inside the hole) cannot be static
  background; those pixels, grown by a margin, are never copied.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from worker.slam.config import valid
from worker.slam.features.matching import cross_checked
from worker.slam.features.types import Features
from worker.slam.geometry.pnp import sqpnp_ransac


@dataclass(frozen=True)
class LookaheadConfig:
    """Future-frame references (both-sided restoration)."""

    min_pnp_inliers: int = valid(40, 6, 10_000)
    """A future frame whose pose PnP-RANSAC supports with fewer inliers is not used."""
    reprojection_px: float = valid(3.0, 0.5, 50.0)
    """PnP-RANSAC inlier threshold."""
    in_front_m: float = valid(0.10, 0.0, 10.0)
    """A future point this much (plus `in_front_rel` of the depth) in front of the target's depth is moving."""
    in_front_rel: float = valid(0.03, 0.0, 1.0)
    max_descriptors: int = valid(300, 20, 100_000)
    """PnP matches at most this many of the target's static keypoints with depth (evenly picked): brute-force
    matching every future candidate against all of them was the look-ahead's largest cost."""
    mask_stride: int = valid(2, 1, 16)
    """The moving-pixel test runs on every n-th pixel (then upsampled): the mask is grown anyway."""
    mask_grow_px: int = valid(9, 0, 100)
    """Moving pixels are grown by this much: a person's edge pixels have depth between body and background."""


def relative_pose_pnp(target: Features, target_static: np.ndarray, future: Features, K: np.ndarray,
                      config: LookaheadConfig) -> tuple[np.ndarray, int] | None:
    """T_ft (4,4): target camera -> future camera, from the target's keypoints with depth whose pixel is
    `target_static` (H,W) bool, matched to `future`'s; None when too few inliers support it."""
    if len(target) == 0 or len(future) == 0:
        return None
    uv_t = target.uv_raw if target.uv_raw is not None else target.uv
    h, w = target_static.shape
    x = np.clip(np.rint(uv_t[:, 0]).astype(int), 0, w - 1)
    y = np.clip(np.rint(uv_t[:, 1]).astype(int), 0, h - 1)
    use = np.flatnonzero((target.depth > 0) & target_static[y, x])
    if len(use) < config.min_pnp_inliers:
        return None
    if len(use) > config.max_descriptors:
        use = use[np.linspace(0, len(use) - 1, config.max_descriptors).astype(int)]
    qi, fi = cross_checked(target.desc[use], future.desc, 63)
    if len(qi) < config.min_pnp_inliers:
        return None
    ti = use[qi]
    z = target.depth[ti].astype(np.float64)
    pts = np.stack([(uv_t[ti, 0] - K[0, 2]) / K[0, 0] * z, (uv_t[ti, 1] - K[1, 2]) / K[1, 1] * z, z], 1)
    uv_f = future.uv_raw if future.uv_raw is not None else future.uv
    got = sqpnp_ransac(pts, uv_f[fi].astype(np.float64), K, config.reprojection_px, 200, config.min_pnp_inliers)
    if got is None:
        return None
    rvec, tvec, inl = got
    rvec, tvec = cv2.solvePnPRefineLM(pts[inl], uv_f[fi][inl].astype(np.float64), K, None, rvec, tvec)
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    return T, len(inl)


def moving_pixels(future_depth: np.ndarray, T_ft: np.ndarray, target_depth: np.ndarray, hole: np.ndarray,
                  K: np.ndarray, config: LookaheadConfig) -> np.ndarray:
    """bool (H,W) of the future frame: pixels whose point lies in front of what the target sees at its
    projection, i.e. in front of static background, or not behind the target's occluder inside `hole`."""
    h, w = future_depth.shape
    s = config.mask_stride
    ys, xs = np.mgrid[0:h:s, 0:w:s]
    z = future_depth[ys, xs].astype(np.float64)
    P = np.stack([(xs - K[0, 2]) / K[0, 0] * z, (ys - K[1, 2]) / K[1, 1] * z, z], -1)
    T_tf = np.linalg.inv(T_ft)
    Q = P @ T_tf[:3, :3].T + T_tf[:3, 3]
    zt = np.maximum(Q[..., 2], 1e-6)
    u = np.rint(Q[..., 0] / zt * K[0, 0] + K[0, 2]).astype(int)
    v = np.rint(Q[..., 1] / zt * K[1, 1] + K[1, 2]).astype(int)
    inside = (z > 0) & (Q[..., 2] > 1e-3) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    uc, vc = np.clip(u, 0, w - 1), np.clip(v, 0, h - 1)
    seen = target_depth[vc, uc]
    margin = config.in_front_m + config.in_front_rel * seen
    # outside the hole: in front of the static surface the target sees; inside it: the background is behind
    # the target's occluder, so a point at or in front of the occluder is an occluder too
    front = np.where(hole[vc, uc], Q[..., 2] < seen + margin, Q[..., 2] < seen - margin)
    small = (inside & (seen > 0) & front).astype(np.uint8)
    mask = cv2.resize(small, (w, h), interpolation=cv2.INTER_NEAREST)[:h, :w]
    k = 2 * config.mask_grow_px + 1
    return cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
