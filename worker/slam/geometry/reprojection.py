"""The RGB-D reprojection residual shared by motion-only BA and local BA.

A keypoint with depth z is treated as a stereo observation (u, v, u_r) with u_r = u - bf/z (ORB-SLAM2's
virtual right camera, bf = fx * baseline): one residual vector mixes image position and depth with the
right relative weight. Keypoints without depth give (u, v) only (third row weighted 0).
Pose perturbations are left-multiplied on T_CW: T_CW <- exp(delta) T_CW, delta = (rho, phi).
"""
from __future__ import annotations

import numpy as np


def project(Pc: np.ndarray, K: np.ndarray, bf: float) -> np.ndarray:
    """(N,3) camera-frame points -> (N,3) predicted (u, v, u_r)."""
    z = Pc[:, 2]
    u = K[0, 0] * Pc[:, 0] / z + K[0, 2]
    v = K[1, 1] * Pc[:, 1] / z + K[1, 2]
    return np.stack([u, v, u - bf / z], axis=1)


def observations(uv: np.ndarray, z: np.ndarray, bf: float) -> tuple[np.ndarray, np.ndarray]:
    """(N,3) measured (u, v, u_r) and (N,) bool 'has depth' from keypoints `uv` (N,2) and depth `z` (N,)."""
    has = z > 0
    ur = np.where(has, uv[:, 0] - bf / np.where(has, z, 1.0), 0.0)
    return np.column_stack([uv, ur]), has


def jacobian_point(Pc: np.ndarray, K: np.ndarray, bf: float) -> np.ndarray:
    """(N,3,3) d(u, v, u_r)/d(Pc)."""
    fx, fy = K[0, 0], K[1, 1]
    x, y, z = Pc[:, 0], Pc[:, 1], Pc[:, 2]
    iz, iz2 = 1.0 / z, 1.0 / z**2
    J = np.zeros((len(Pc), 3, 3))
    J[:, 0, 0] = fx * iz
    J[:, 0, 2] = -fx * x * iz2
    J[:, 1, 1] = fy * iz
    J[:, 1, 2] = -fy * y * iz2
    J[:, 2, 0] = fx * iz
    J[:, 2, 2] = (-fx * x + bf) * iz2
    return J


def jacobian_pose(Pc: np.ndarray, Jp: np.ndarray) -> np.ndarray:
    """(N,3,6) d(u, v, u_r)/d(delta) given d/dPc `Jp` (N,3,3); dPc/d(delta) = [I, -hat(Pc)].

    Row r of Jp @ -hat(Pc) is (Pc x r), so the rotation block is a batched cross product.
    """
    x, y, z = Pc[:, 0, None], Pc[:, 1, None], Pc[:, 2, None]
    r0, r1, r2 = Jp[:, :, 0], Jp[:, :, 1], Jp[:, :, 2]
    J = np.empty((len(Pc), 3, 6))
    J[:, :, :3] = Jp
    J[:, :, 3] = y * r2 - z * r1
    J[:, :, 4] = z * r0 - x * r2
    J[:, :, 5] = x * r1 - y * r0
    return J


def residual_weights(has_depth: np.ndarray) -> np.ndarray:
    """(N,3) per-row weights: the u_r row counts only where the keypoint has depth."""
    w = np.ones((len(has_depth), 3))
    w[~has_depth, 2] = 0.0
    return w


def huber_weights(chi2: np.ndarray, delta: float) -> np.ndarray:
    """IRLS weights of the Huber kernel on the Mahalanobis norm sqrt(chi2)."""
    e = np.sqrt(np.maximum(chi2, 1e-12))
    return np.where(e <= delta, 1.0, delta / e)
