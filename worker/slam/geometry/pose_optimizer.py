"""Motion-only bundle adjustment: Gauss-Newton on one pose with a Huber kernel and outlier rounds.

As ORB-SLAM2's PoseOptimization: several rounds; after each round observations whose chi-square exceeds the
95% threshold (7.815 with depth, 5.991 without) are set aside, and the robust kernel is dropped for the last
rounds. The pose covariance comes from the Gauss-Newton normal equations at the solution. Optional prior weights
per match (how far its map point is to be trusted) scale each residual's weight in the solve; the outlier tests
and the covariance ignore them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.geometry import reprojection as rp
from worker.slam.geometry.se3 import exp_se3, inv, orthonormalize

CHI2_STEREO, CHI2_MONO = 7.815, 5.991


@dataclass
class PoseEstimate:
    """Result of motion-only BA.

    `T_WC` 4x4 float64. `inliers` (N,) bool. `covariance` (6,6): covariance of the left perturbation
    delta = (rho, phi) of T_CW (metres, radians), (J^T Omega J)^-1 over the inliers with a 1-pixel keypoint
    sigma at octave 0 (scaled by the octave); None if the system is singular.
    """

    T_WC: np.ndarray
    inliers: np.ndarray
    covariance: np.ndarray | None
    chi2: np.ndarray

    @property
    def n_inliers(self) -> int:
        return int(self.inliers.sum())


def optimize_pose(T_WC: np.ndarray, X_w: np.ndarray, uv: np.ndarray, z: np.ndarray, info: np.ndarray,
                  K: np.ndarray, bf: float, huber_px: float = 2.45, rounds: int = 4,
                  iterations: int = 8, weights: np.ndarray | None = None,
                  depth_w: np.ndarray | None = None) -> PoseEstimate:
    """Refine `T_WC` from (N,3) world points `X_w` seen at (N,2) pixels `uv` with (N,) depths `z` (0 = none).

    `info` (N,) inverse variance of each keypoint (1/scale^2 of its octave). `bf` = fx * virtual baseline.
    `weights` (N,) prior weight of each match in (0, 1], multiplying the robust weights (None = all 1).
    `depth_w` (N,) scale of each depth residual (`features.depth.depth_weights`; None = all 1); given, the
    depth row is the disparity alone (`reprojection`, `ur_u` 0).
    """
    n = len(X_w)
    T_CW = inv(T_WC)
    ur_u = 1.0 if depth_w is None else 0.0
    obs, has = rp.observations(uv, z, bf, ur_u)
    roww = rp.residual_weights(has, depth_w)
    thr = np.where(has, CHI2_STEREO, CHI2_MONO)
    prior = np.ones(n) if weights is None else np.asarray(weights, np.float64)
    inl = np.ones(n, bool)
    chi2 = np.zeros(n)
    for rnd in range(rounds):
        robust = rnd < rounds - 2
        for _ in range(iterations):
            Pc = X_w @ T_CW[:3, :3].T + T_CW[:3, 3]
            good = inl & (Pc[:, 2] > 1e-3)
            if good.sum() < 3:
                break
            e, J, Jw = rp.pose_step_terms(Pc, obs, roww, info, good, prior, K[0, 0], K[1, 1], K[0, 2], K[1, 2],
                                          float(bf), float(huber_px), robust, ur_u)
            Jw = Jw.reshape(-1, 6)
            H = Jw.T @ J.reshape(-1, 6)
            b = Jw.T @ e.ravel()
            try:
                delta = np.linalg.solve(H, b)
            except np.linalg.LinAlgError:
                break
            T_CW = exp_se3(delta) @ T_CW
            if np.linalg.norm(delta) < 1e-6:  # a micrometre / microradian: converged
                break
        Pc = X_w @ T_CW[:3, :3].T + T_CW[:3, 3]
        front = Pc[:, 2] > 1e-3
        e = (obs - rp.project(np.where(front[:, None], Pc, 1.0), K, bf, ur_u)) * roww
        chi2 = np.where(front, info * (e**2).sum(1), np.inf)
        inl = chi2 < thr
        if inl.sum() < 10:
            break
    T_CW = orthonormalize(T_CW)
    return PoseEstimate(inv(T_CW), inl, _covariance(T_CW, X_w[inl], info[inl], roww[inl], K, bf, ur_u), chi2)


def _covariance(T_CW: np.ndarray, X_w: np.ndarray, info: np.ndarray, roww: np.ndarray, K: np.ndarray,
                bf: float, ur_u: float) -> np.ndarray | None:
    if len(X_w) < 4:
        return None
    Pc = X_w @ T_CW[:3, :3].T + T_CW[:3, 3]
    J = rp.jacobian_pose(Pc, rp.jacobian_point(Pc, K, bf, ur_u)) * roww[:, :, None]
    Jf = J.reshape(-1, 6)
    H = (J * info[:, None, None]).reshape(-1, 6).T @ Jf
    try:
        return np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return None


def pose_entropy(covariance: np.ndarray) -> float:
    """Differential entropy H = 1/2 ln((2 pi e)^k |Sigma|) of a pose covariance (k = 6)."""
    k = covariance.shape[0]
    sign, logdet = np.linalg.slogdet(covariance)
    if sign <= 0:
        return float("inf")
    return float(0.5 * (k * np.log(2 * np.pi * np.e) + logdet))
