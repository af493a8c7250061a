"""One object's rigid motion between two frames and its covariance, for the per-object threshold Δd = f(H).

The paper derives the epipolar threshold of each object from the differential entropy of that object's own
motion estimate rather than the camera's. Here the motion is the rigid transform T (4x4, X_cur = T X_prev)
that maps the object's previous-camera points (from the previous depth) onto its current keypoints, found by
Gauss–Newton from the camera's relative pose (the object's motion is the camera's when it is static). Its
covariance is the inverse of the normal equations scaled by the residual variance, Σ = s² (JᵀJ)⁻¹ with
s² = Σr² / (2N − k): few, spread-out or badly matched points give a wide Σ, a high entropy and a wide Δd.
With fewer than `min_points_6dof` points only the translation (k = 3) is estimated, the rotation held at the
camera's; fewer than `min_points` points give no estimate (the caller then uses the frame-level Δd).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from worker.slam.config import valid


@dataclass(frozen=True)
class ObjectMotionConfig:
    min_points: int = valid(4, 2, 100_000)
    """Fewer matched points with depth on a segment than this: no object-level estimate (frame-level Δd)."""
    min_points_6dof: int = valid(8, 3, 100_000)
    """From this many points the full 6-DoF motion is estimated; below, a 3-DoF translation."""
    iterations: int = valid(8, 1, 100)
    """Gauss–Newton iterations (it starts at the camera's motion, a few pixels from the object's)."""
    min_sigma_px: float = valid(0.3, 0.0, 100.0)
    """Floor of the residual standard deviation: with as many unknowns as equations, or a perfect fit, the
    residual variance is 0 and would claim an exact motion."""


@dataclass(frozen=True)
class ObjectMotion:
    """`T` 4x4 (X_cur = T X_prev); `cov` k×k over (translation, rotation) or (translation,); RMS residual px."""

    T: np.ndarray
    cov: np.ndarray
    rms_px: float
    points: int


def _jacobian(P: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N, 2, 6) derivative of the pixel projections of camera points P (N, 3) w.r.t. a left perturbation
    (ρ, φ) of the motion: d(u, v)/dP · [I | −[P]×]."""
    fx, fy = K[0, 0], K[1, 1]
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    zero = np.zeros_like(z)
    dproj = np.stack([np.stack([fx / z, zero, -fx * x / z**2], 1),
                      np.stack([zero, fy / z, -fy * y / z**2], 1)], 1)  # (N, 2, 3)
    skew = np.zeros((len(P), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -z, y, -x
    skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = z, -y, x
    dP = np.concatenate([np.broadcast_to(np.eye(3), (len(P), 3, 3)), -skew], 2)  # (N, 3, 6)
    return dproj @ dP


def _project(P: np.ndarray, K: np.ndarray) -> np.ndarray:
    return (P[:, :2] / P[:, 2:3]) * np.diag(K)[:2] + K[:2, 2]


def estimate_object_motion(X_prev: np.ndarray, uv_cur: np.ndarray, K: np.ndarray, T_init: np.ndarray | None,
                           config: ObjectMotionConfig = ObjectMotionConfig()) -> ObjectMotion | None:
    """The object's motion from its previous-camera points X_prev (N, 3) m seen at uv_cur (N, 2) px in the
    current frame, starting at T_init (4x4, the camera's relative motion; None = identity). None when there
    are too few points, a point falls behind the camera or the normal equations are singular."""
    n = len(X_prev)
    if n < config.min_points:
        return None
    k = 6 if n >= config.min_points_6dof else 3
    T = np.eye(4) if T_init is None else T_init.astype(np.float64).copy()
    uv = uv_cur.astype(np.float64)
    for _ in range(config.iterations):
        P = X_prev @ T[:3, :3].T + T[:3, 3]
        if np.any(P[:, 2] <= 1e-6):
            return None
        r = (_project(P, K) - uv).reshape(-1)  # (2N,)
        J = _jacobian(P, K)[:, :, :k].reshape(-1, k)
        H = J.T @ J
        try:
            step = -np.linalg.solve(H, J.T @ r)
        except np.linalg.LinAlgError:
            return None
        dR = cv2.Rodrigues(step[3:6].reshape(3, 1))[0] if k == 6 else np.eye(3)
        T = np.vstack([np.hstack([dR @ T[:3, :3], (dR @ T[:3, 3] + step[:3]).reshape(3, 1)]), [0, 0, 0, 1]])
        if np.linalg.norm(step) < 1e-10:
            break
    P = X_prev @ T[:3, :3].T + T[:3, 3]
    if np.any(P[:, 2] <= 1e-6):
        return None
    r = (_project(P, K) - uv).reshape(-1)
    J = _jacobian(P, K)[:, :, :k].reshape(-1, k)
    dof = max(2 * n - k, 1)
    s2 = max(float(r @ r) / dof, config.min_sigma_px**2)
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return None
    return ObjectMotion(T, cov, float(np.sqrt(np.mean(r**2))), n)
