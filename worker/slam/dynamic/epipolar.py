"""Matches between two frames, the fundamental matrix from static matches, epipolar distances.

Matching is guided when the tracker can predict the relative pose: each previous keypoint is projected into
the current frame (with its depth, or at infinity without) and matched among the current keypoints near the
prediction. This is a k-d tree query per point instead of a brute-force N×M descriptor comparison, and the
search radius also leaves room for the object motion that culling is looking for.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from worker.slam.features.matching import cross_checked
from worker.slam.features.search import KeypointIndex, match_near_predictions


@dataclass(frozen=True)
class Matches:
    """Indices into the previous (`prev_idx`) and current (`cur_idx`) keypoint arrays, (N,) each."""

    prev_idx: np.ndarray
    cur_idx: np.ndarray


def match_orb(desc_prev: np.ndarray, desc_cur: np.ndarray, max_distance: int = 50) -> Matches:
    """Cross-checked Hamming matches of ORB descriptors (N, 32) uint8."""
    if desc_prev is None or desc_cur is None:
        return Matches(np.zeros(0, int), np.zeros(0, int))
    return Matches(*cross_checked(desc_prev, desc_cur, max_distance))


def predict_positions(uv_prev: np.ndarray, z_prev: np.ndarray, T_cur_prev: np.ndarray,
                      K: np.ndarray) -> np.ndarray:
    """Where (N,2) keypoints `uv_prev` px of the previous frame appear in the current one under `T_cur_prev`
    (4x4, X_cur = T X_prev): back-projected with depth `z_prev` (N,) m, or as directions (at infinity, so
    only the rotation moves them) where the depth is 0. Points that land behind the camera get NaN."""
    rays = np.column_stack([(uv_prev[:, 0] - K[0, 2]) / K[0, 0], (uv_prev[:, 1] - K[1, 2]) / K[1, 1],
                            np.ones(len(uv_prev))])
    has = z_prev > 0
    X = rays @ T_cur_prev[:3, :3].T
    X[has] += T_cur_prev[:3, 3] / z_prev[has, None]  # (R z ray + t) / z: the same direction, scaled
    z = X[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.column_stack([K[0, 0] * X[:, 0] / z + K[0, 2], K[1, 1] * X[:, 1] / z + K[1, 2]])
    uv[z <= 1e-6] = np.nan
    return uv


def match_guided(uv_prev: np.ndarray, z_prev: np.ndarray, desc_prev: np.ndarray, cur: KeypointIndex,
                 T_cur_prev: np.ndarray, K: np.ndarray, radius_px: float = 24.0, max_distance: int = 50,
                 ratio: float = 0.9, pred: np.ndarray | None = None) -> Matches:
    """Matches of previous keypoints (N,2) px, depth (N,) m, ORB (N,32) to the current frame's keypoints
    (`cur`) within `radius_px` of their predicted positions (twice that without depth: no parallax known).
    `pred` (N,2) px: those positions when the caller has them (`predict_positions`), else computed here."""
    pred = predict_positions(uv_prev, z_prev, T_cur_prev, K) if pred is None else pred
    inside = np.flatnonzero(np.isfinite(pred).all(1))
    radius = np.where(z_prev[inside] > 0, radius_px, 2 * radius_px)
    pi, ci = match_near_predictions(cur, pred[inside], desc_prev[inside], radius, max_distance, ratio)
    return Matches(inside[pi], ci)


def fundamental_ransac(p_prev: np.ndarray, p_cur: np.ndarray, threshold_px: float = 1.0,
                       confidence: float = 0.999, usac: bool = False) -> np.ndarray | None:
    """F (3x3) with x_cur^T F x_prev = 0 from pixel points (N, 2), RANSAC over eight-point solutions
    (`usac`: OpenCV's USAC, with local optimisation and degeneracy checks)."""
    if len(p_prev) < 8:
        return None
    method = cv2.USAC_DEFAULT if usac else cv2.FM_RANSAC
    F, _ = cv2.findFundamentalMat(p_prev.astype(np.float64), p_cur.astype(np.float64), method,
                                  threshold_px, confidence)
    if F is None or F.shape != (3, 3):
        return None
    return F


def fundamental_from_seed(p_prev: np.ndarray, p_cur: np.ndarray, F_seed: np.ndarray, threshold_px: float = 1.0,
                          min_inliers: float = 0.5, rounds: int = 2) -> np.ndarray | None:
    """F (3x3) fitted by least squares (OpenCV's eight-point) to the matches (N, 2) px that `F_seed` explains
    within `threshold_px`, then to those the fit explains, `rounds` times while the consensus does not shrink;
    None when the seed explains fewer than `min_inliers` of them (the caller falls back to RANSAC).

    The seed is the fundamental matrix of a pose that is already known (`fundamental_of_pose`): it plays the
    part of RANSAC's best hypothesis, so the ~900 random seven-point hypotheses are not needed."""
    if len(p_prev) < 8 or not np.abs(F_seed).max() > 0:  # no translation: the seed has no epipolar lines
        return None
    inl = epipolar_distance(F_seed, p_prev, p_cur) < threshold_px
    if inl.mean() < min_inliers:
        return None
    F = F_seed
    for _ in range(rounds):
        if inl.sum() < 8:
            break
        fit, _ = cv2.findFundamentalMat(p_prev[inl].astype(np.float64), p_cur[inl].astype(np.float64),
                                        cv2.FM_8POINT)
        if fit is None or fit.shape != (3, 3):
            break
        fit_inl = epipolar_distance(fit, p_prev, p_cur) < threshold_px
        if fit_inl.sum() < inl.sum():
            break
        F, inl = fit, fit_inl
    return F


def fundamental_of_pose(R: np.ndarray, t: np.ndarray, K: np.ndarray) -> np.ndarray:
    """F (3x3) with x_cur^T F x_prev = 0 for the relative pose X_cur = R X_prev + t and intrinsics K:
    K^-T [t]x R K^-1."""
    K_inv = np.linalg.inv(K)
    t = np.asarray(t, np.float64).ravel()
    t_x = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    return K_inv.T @ t_x @ R @ K_inv


def epipolar_distance(F: np.ndarray, p_prev: np.ndarray, p_cur: np.ndarray) -> np.ndarray:
    """Distance (N,) in pixels of each current point to the epipolar line F x_prev of its match."""
    ones = np.ones((len(p_prev), 1))
    lines = np.hstack([p_prev, ones]) @ F.T  # (a, b, c) per match, in the current image
    num = np.abs(np.sum(lines * np.hstack([p_cur, ones]), axis=1))
    return num / np.maximum(np.hypot(lines[:, 0], lines[:, 1]), 1e-12)
