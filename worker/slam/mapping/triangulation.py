"""New map points triangulated between keyframes for keypoints that got none from depth (ORB-SLAM2's
CreateNewMapPoints): no depth, or beyond `new_point_max_depth_m`, so far structure is used too.

Per pair (new keyframe, a covisible one): descriptor matches among keypoints without a map point in either,
kept when the second lies near the first's epipolar line, the rays meet at enough parallax, the point is in
front of both cameras and reprojects within the chi-square bound in both.
"""
from __future__ import annotations

import cv2
import numpy as np

from worker.slam.features.matching import match_ratio
from worker.slam.geometry.se3 import inv
from worker.slam.map.keyframe import KeyFrame
from worker.slam.map.map import Map

CHI2_2DOF = 5.991
"""95 % bound of a 2-dof squared reprojection error in units of the keypoint's variance."""


def _fundamental(T_WC1: np.ndarray, T_WC2: np.ndarray, K: np.ndarray) -> np.ndarray:
    """F with x2^T F x1 = 0 for pixels x1 in camera 1, x2 in camera 2 (3,3)."""
    T21 = inv(T_WC2) @ T_WC1
    R, t = T21[:3, :3], T21[:3, 3]
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    Ki = np.linalg.inv(K)
    return Ki.T @ tx @ R @ Ki


def _reproj_err2(X: np.ndarray, T_WC: np.ndarray, K: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(squared pixel error (N,), depth (N,)) of world points X (N,3) seen by camera T_WC at keypoints uv (N,2)."""
    T = inv(T_WC)
    Pc = X @ T[:3, :3].T + T[:3, 3]
    z = Pc[:, 2]
    proj = Pc[:, :2] / np.where(np.abs(z) > 1e-9, z, 1e-9)[:, None] * np.diag(K)[:2] + K[:2, 2]
    return ((proj - uv) ** 2).sum(1), z


def triangulate_pair(slam_map: Map, kf1: KeyFrame, kf2: KeyFrame, K: np.ndarray, inv_sigma2: np.ndarray,
                     scale_factor: float, min_parallax_deg: float) -> int:
    """Create map points from matches between the point-less keypoints of two keyframes. Returns the count."""
    free1 = np.flatnonzero(kf1.point_ids < 0)
    free2 = np.flatnonzero(kf2.point_ids < 0)
    if len(free1) < 8 or len(free2) < 8:
        return 0
    q, t = match_ratio(kf1.feats.desc[free1], kf2.feats.desc[free2], ratio=0.7, max_dist=50)
    i1, i2 = free1[q], free2[t]
    if len(i1) == 0:
        return 0
    f1, f2 = kf1.feats, kf2.feats
    uv1, uv2 = f1.uv[i1], f2.uv[i2]
    # epipolar distance of x2 to F x1, within 2 sigma of the second keypoint's scale
    F = _fundamental(kf1.T_WC, kf2.T_WC, K)
    lines = np.column_stack([uv1, np.ones(len(uv1))]) @ F.T
    d2 = (np.column_stack([uv2, np.ones(len(uv2))]) * lines).sum(1) ** 2 / (lines[:, :2] ** 2).sum(1)
    ok = d2 * inv_sigma2[f2.octave[i2]] < 3.84 * 4
    # parallax between the two viewing rays
    Ki = np.linalg.inv(K)
    r1 = np.column_stack([uv1, np.ones(len(uv1))]) @ Ki.T @ kf1.T_WC[:3, :3].T
    r2 = np.column_stack([uv2, np.ones(len(uv2))]) @ Ki.T @ kf2.T_WC[:3, :3].T
    cos = (r1 * r2).sum(1) / (np.linalg.norm(r1, axis=1) * np.linalg.norm(r2, axis=1))
    ok &= cos < np.cos(np.radians(min_parallax_deg))
    if not ok.any():
        return 0
    i1, i2, uv1, uv2 = i1[ok], i2[ok], uv1[ok], uv2[ok]
    P1 = K @ inv(kf1.T_WC)[:3]
    P2 = K @ inv(kf2.T_WC)[:3]
    Xh = cv2.triangulatePoints(P1, P2, uv1.T.astype(np.float64), uv2.T.astype(np.float64))
    X = (Xh[:3] / np.where(np.abs(Xh[3]) > 1e-12, Xh[3], 1e-12)).T
    e1, z1 = _reproj_err2(X, kf1.T_WC, K, uv1)
    e2, z2 = _reproj_err2(X, kf2.T_WC, K, uv2)
    good = (z1 > 0) & (z2 > 0) & np.isfinite(X).all(1)
    good &= (e1 * inv_sigma2[f1.octave[i1]] < CHI2_2DOF) & (e2 * inv_sigma2[f2.octave[i2]] < CHI2_2DOF)
    if not good.any():
        return 0
    i1, i2, X = i1[good], i2[good], X[good]
    p = slam_map.points
    ids = p.add(X, f1.desc[i1], kf1.center, f1.octave[i1], scale_factor, kf1.id)
    p.n_obs[ids] += 1
    kf1.point_ids[i1] = ids
    kf2.point_ids[i2] = ids
    return len(ids)


def triangulate_new_points(slam_map: Map, kf: KeyFrame, neighbours: int, K: np.ndarray, inv_sigma2: np.ndarray,
                           scale_factor: float, min_parallax_deg: float) -> int:
    """Triangulate between `kf` and its `neighbours` best covisible keyframes; update covisibility."""
    n = 0
    for j in slam_map.best_covisible(kf.id, neighbours):
        n += triangulate_pair(slam_map, kf, slam_map.keyframes[j], K, inv_sigma2, scale_factor, min_parallax_deg)
    if n:
        slam_map.update_covisibility(kf.id)
    return n
