"""Every frame's final pose smoothed under a constant-velocity motion prior, weighted by its covariance.

Each tracked frame's pose, solved alone against the final map (`frame_refit`), is a measurement with a 6x6
information matrix from its motion-only BA. With ~1-pixel keypoints (integer FAST corners, coarser at higher
pyramid levels) a single frame's solve is good to about a millimetre along the optical axis, which depth pins,
but only to several millimetres sideways (camera x and y, where a shift and a rotation move the image nearly
alike), independently from frame to frame: on the synthetic room (exact truth) the frame-to-frame RPE was 7.9 mm
against an ATE of 6.8 mm, and the scatter matched the solves' own covariances (docs/results/jitter.md).

A hand-held camera's motion is smooth at 30 Hz, so all frames are solved together (a batch smoother): the
measurement factors keep each frame near its own solve, weighted by that solve's information (so it moves
along the ill-determined direction and barely along the others), and a white-noise-on-acceleration prior
(Barfoot's constant-velocity Gaussian process, discretised as second differences at the frames' true time
stamps) ties every three consecutive tracked frames. Both kinds of residual are Huber-weighted (iteratively
reweighted Gauss-Newton), so a mis-tracked frame or a real jolt does not smear into its neighbours. Poses are
(position, world-frame rotation vector) perturbations; the normal equations are block-banded and solved with
scipy's sparse solver (300 frames: a few milliseconds per iteration).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial.transform import Rotation

CHI2_POSE_95 = 12.59  # 95 % chi-square of 6 degrees of freedom: where the measurement Huber kernel starts


@dataclass(frozen=True)
class SmootherSettings:
    """`accel_sigma` m/s^2 per sqrt(Hz) and `angular_sigma` rad/s^2 per sqrt(Hz): the power spectral density
    (square root) of the white-noise acceleration; `pixel_sigma` the keypoint noise (pixels, octave 0) that
    scales the measurements' information; `huber_accel` the Huber threshold of the prior's whitened residuals;
    `iterations` Gauss-Newton iterations."""

    accel_sigma: float = 0.15
    angular_sigma: float = 0.5
    pixel_sigma: float = 1.0
    huber_accel: float = 3.0
    iterations: int = 4


def world_information(T_WC: np.ndarray, info_cw: np.ndarray) -> np.ndarray:
    """(6,6) information of the (position, world rotation vector) perturbation of `T_WC` (4,4), from `info_cw`
    (6,6), the information of motion-only BA's left perturbation (rho, phi) of T_CW (`PoseEstimate`).
    T_CW <- exp(d) T_CW is T_WC <- T_WC exp(-d): position -R rho, world rotation -R phi (first order)."""
    J = np.zeros((6, 6))
    J[:3, :3] = J[3:, 3:] = T_WC[:3, :3]
    return J @ info_cw @ J.T


def smooth_poses(poses: np.ndarray, stamps: np.ndarray, info: list[np.ndarray | None],
                 s: SmootherSettings) -> np.ndarray:
    """Smoothed copy of `poses` (F,4,4) T_WC at `stamps` (F,) s. `info[k]` (6,6) is frame k's measurement
    information in `world_information`'s coordinates, at pixel sigma 1; None: the frame is not smoothed (lost,
    not refitted) and breaks the motion prior, which ties only unbroken runs of three frames."""
    F = len(poses)
    meas = np.array([m is not None for m in info], dtype=bool)
    triples = np.flatnonzero(meas[:-2] & meas[1:-1] & meas[2:]) if F >= 3 else np.zeros(0, int)
    if not len(triples):
        return poses.copy()
    idx = np.flatnonzero(meas)
    col = -np.ones(F, int)
    col[idx] = np.arange(len(idx))
    lam = np.stack([m for m in info if m is not None]) / s.pixel_sigma**2  # the frames of `idx`, in order
    # whitening of the second differences: velocity change over the mean interval, PSD q
    dt = np.maximum(np.diff(stamps), 1e-3)
    dt0, dt1 = dt[triples], dt[triples + 1]
    q = np.array([s.accel_sigma] * 3 + [s.angular_sigma] * 3)
    white = 1.0 / (q[None, :] * np.sqrt(0.5 * (dt0 + dt1))[:, None])  # (T,6)
    p0, R0 = poses[idx, :3, 3].copy(), Rotation.from_matrix(poses[idx, :3, :3])
    p, R = p0.copy(), R0
    for _ in range(s.iterations):
        dx = _step(p, R, p0, R0, lam, col[triples], dt0, dt1, white, s.huber_accel)
        p = p + dx[:, :3]
        R = Rotation.from_rotvec(dx[:, 3:]) * R
        if np.abs(dx).max() < 1e-7:
            break
    out = poses.copy()
    out[idx, :3, 3] = p
    out[idx, :3, :3] = R.as_matrix()
    return out


def _step(p: np.ndarray, R: Rotation, p0: np.ndarray, R0: Rotation, lam: np.ndarray, t: np.ndarray,
          dt0: np.ndarray, dt1: np.ndarray, white: np.ndarray, huber: float) -> np.ndarray:
    """One reweighted Gauss-Newton step (N,6) of the N measured frames; `t` (T,) the first frame (column) of
    each prior triple."""
    n = len(p)
    # measurement residuals r = x - x_meas in the perturbation coordinates, Huber on their chi-square
    r_m = np.concatenate([p - p0, (R * R0.inv()).as_rotvec()], axis=1)
    chi2 = np.einsum("ni,nij,nj->n", r_m, lam, r_m)
    w_m = np.where(chi2 > CHI2_POSE_95, np.sqrt(CHI2_POSE_95 / np.maximum(chi2, 1e-12)), 1.0)
    H_m = lam * w_m[:, None, None]
    g = -np.einsum("nij,nj->ni", H_m, r_m)
    # prior residuals: v1 - v0 per component (a = (x2-x1)/dt1 - (x1-x0)/dt0), whitened
    a, b, c = t, t + 1, t + 2
    dp = (p[c] - p[b]) / dt1[:, None] - (p[b] - p[a]) / dt0[:, None]
    w1 = (R[c] * R[b].inv()).as_rotvec() / dt1[:, None]
    w0 = (R[b] * R[a].inv()).as_rotvec() / dt0[:, None]
    e = np.concatenate([dp, w1 - w0], axis=1) * white  # (T,6)
    mag = np.abs(e)
    w_p = np.where(mag > huber, huber / np.maximum(mag, 1e-12), 1.0) * white**2  # per-component weight
    coef = np.stack([1.0 / dt0, -(1.0 / dt0 + 1.0 / dt1), 1.0 / dt1], axis=1)  # d e / d x_{a,b,c}
    rows, cols, vals = [np.repeat(np.arange(n) * 6, 36) + np.tile(np.repeat(np.arange(6), 6), n)], \
        [np.repeat(np.arange(n) * 6, 36) + np.tile(np.tile(np.arange(6), 6), n)], [H_m.ravel()]
    e_raw = e / white
    for i, ni in enumerate((a, b, c)):
        for j, nj in enumerate((a, b, c)):
            v = coef[:, i:i + 1] * coef[:, j:j + 1] * w_p  # (T,6) diagonal blocks per component
            rows.append((ni[:, None] * 6 + np.arange(6)).ravel())
            cols.append((nj[:, None] * 6 + np.arange(6)).ravel())
            vals.append(v.ravel())
    for i, ni in enumerate((a, b, c)):
        np.add.at(g, ni, -coef[:, i:i + 1] * w_p * e_raw)
    H = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(6 * n, 6 * n))
    return spla.spsolve(H, g.ravel()).reshape(n, 6)
