"""The RGB-D reprojection residual shared by motion-only BA and local BA.

A keypoint with depth z is treated as a stereo observation (u, v, u_r) with u_r = u - bf/z (ORB-SLAM2's
virtual right camera, bf = fx * baseline): one residual vector mixes image position and depth with the
right relative weight. Keypoints without depth give (u, v) only (third row weighted 0). With `ur_u` 0 the third
row is the disparity -bf/z alone: needed when each depth residual has its own weight, since u_r = u - bf/z
carries u's pixel noise, which a heavier third row would multiply.
Pose perturbations are left-multiplied on T_CW: T_CW <- exp(delta) T_CW, delta = (rho, phi).
"""
from __future__ import annotations

import numpy as np
from numba import njit


def project(Pc: np.ndarray, K: np.ndarray, bf: float, ur_u: float = 1.0) -> np.ndarray:
    """(N,3) camera-frame points -> (N,3) predicted (u, v, u_r), u_r = ur_u * u - bf/z."""
    z = Pc[:, 2]
    u = K[0, 0] * Pc[:, 0] / z + K[0, 2]
    v = K[1, 1] * Pc[:, 1] / z + K[1, 2]
    return np.stack([u, v, ur_u * u - bf / z], axis=1)


def observations(uv: np.ndarray, z: np.ndarray, bf: float, ur_u: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(N,3) measured (u, v, u_r) and (N,) bool 'has depth' from keypoints `uv` (N,2) and depth `z` (N,)."""
    has = z > 0
    ur = np.where(has, ur_u * uv[:, 0] - bf / np.where(has, z, 1.0), 0.0)
    return np.column_stack([uv, ur]), has


def jacobian_point(Pc: np.ndarray, K: np.ndarray, bf: float, ur_u: float = 1.0) -> np.ndarray:
    """(N,3,3) d(u, v, u_r)/d(Pc)."""
    fx, fy = K[0, 0], K[1, 1]
    x, y, z = Pc[:, 0], Pc[:, 1], Pc[:, 2]
    iz, iz2 = 1.0 / z, 1.0 / z**2
    J = np.zeros((len(Pc), 3, 3))
    J[:, 0, 0] = fx * iz
    J[:, 0, 2] = -fx * x * iz2
    J[:, 1, 1] = fy * iz
    J[:, 1, 2] = -fy * y * iz2
    J[:, 2, 0] = ur_u * fx * iz
    J[:, 2, 2] = (-ur_u * fx * x + bf) * iz2
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


def residual_weights(has_depth: np.ndarray, depth_w: np.ndarray | None = None) -> np.ndarray:
    """(N,3) per-row weights: the u_r row counts only where the keypoint has depth, scaled by `depth_w` (N,)
    (each keypoint's depth sigma against the virtual baseline's; None = 1)."""
    w = np.ones((len(has_depth), 3))
    if depth_w is not None:
        w[:, 2] = depth_w
    w[~has_depth, 2] = 0.0
    return w


def huber_weights(chi2: np.ndarray, delta: float) -> np.ndarray:
    """IRLS weights of the Huber kernel on the Mahalanobis norm sqrt(chi2)."""
    e = np.sqrt(np.maximum(chi2, 1e-12))
    return np.where(e <= delta, 1.0, delta / e)


@njit(cache=True, nogil=True)
def pose_step_terms(Pc, obs, roww, info, good, prior, fx, fy, cx, cy, bf, huber_px, robust, ur_u):
    """One Gauss-Newton step's per-observation terms of motion-only BA, in one compiled pass: the weighted
    residuals `e` (N,3), the pose Jacobian `J` (N,3,6) (rows weighted by `roww`) and `Jw` = J x the IRLS
    weights (N,3,6): `info` x Huber on chi2 (when `robust`) x `prior` (N,), 0 where not `good`. The same
    operations in the same order as `project`, `jacobian_point`, `jacobian_pose` and `huber_weights` (so the
    same bits: the normal equations are then formed by the caller's matrix products); ~6x fewer passes over
    the points than the numpy expressions, which allocate an array per operation."""
    n = Pc.shape[0]
    e = np.empty((n, 3))
    J = np.empty((n, 3, 6))
    Jw = np.empty((n, 3, 6))
    jp, jc = np.zeros((3, 3)), np.zeros((3, 6))
    for i in range(n):
        x, y, z = Pc[i, 0], Pc[i, 1], Pc[i, 2]
        # the residual at the point, or at (1, 1, 1) behind the camera (its weight is 0)
        px, py, pz = (x, y, z) if z > 1e-3 else (1.0, 1.0, 1.0)
        u = fx * px / pz + cx
        v = fy * py / pz + cy
        ur = ur_u * u - bf / pz
        e[i, 0] = (obs[i, 0] - u) * roww[i, 0]
        e[i, 1] = (obs[i, 1] - v) * roww[i, 1]
        e[i, 2] = (obs[i, 2] - ur) * roww[i, 2]
        chi2 = info[i] * (e[i, 0] ** 2 + e[i, 1] ** 2 + e[i, 2] ** 2)
        w = info[i]
        if robust:
            r = np.sqrt(max(chi2, 1e-12))
            w = w * (1.0 if r <= huber_px else huber_px / r)
        w = w * prior[i] if good[i] else 0.0
        point_jacobian_rows(x, y, z, fx, fy, bf, jp, ur_u)
        pose_jacobian_rows(x, y, z, jp, jc)
        for r in range(3):
            for c in range(6):
                J[i, r, c] = jc[r, c] * roww[i, r]
                Jw[i, r, c] = J[i, r, c] * w
    return e, J, Jw


@njit(cache=True, nogil=True)
def point_jacobian_rows(x, y, z, fx, fy, bf, out, ur_u):
    """`jacobian_point` of one camera-frame point (x, y, z) into `out` (3,3), the same operations in the same order
    (for the compiled BA kernels)."""
    iz, iz2 = 1.0 / z, 1.0 / z**2
    out[:] = 0.0
    out[0, 0] = fx * iz
    out[0, 2] = -fx * x * iz2
    out[1, 1] = fy * iz
    out[1, 2] = -fy * y * iz2
    out[2, 0] = ur_u * fx * iz
    out[2, 2] = (-ur_u * fx * x + bf) * iz2


@njit(cache=True, nogil=True)
def pose_jacobian_rows(x, y, z, jp, out):
    """`jacobian_pose` of one camera-frame point (x, y, z) with d/dPc `jp` (3,3) into `out` (3,6): [jp, Pc x row],
    the same operations in the same order (for the compiled BA kernels)."""
    for r in range(3):
        r0, r1, r2 = jp[r, 0], jp[r, 1], jp[r, 2]
        out[r, 0], out[r, 1], out[r, 2] = r0, r1, r2
        out[r, 3], out[r, 4], out[r, 5] = y * r2 - z * r1, z * r0 - x * r2, x * r1 - y * r0
