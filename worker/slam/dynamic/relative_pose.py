"""The current camera's pose relative to the previous one, fitted to the static matches that have depth: for
the depth test's reprojection error and the prediction veto."""
from __future__ import annotations

import cv2
import numpy as np

from worker.slam.dynamic.culling_config import CullingConfig
from worker.slam.geometry.pnp import reprojection_px, sqpnp_ransac


def spread(idx: np.ndarray, n: int) -> np.ndarray:
    """At most `n` of `idx`, evenly spaced (deterministic, and spread over the keypoint order)."""
    return idx if len(idx) <= n else idx[np.linspace(0, len(idx) - 1, n).astype(int)]


def refine_from(X: np.ndarray, uv: np.ndarray, K: np.ndarray, T_init: np.ndarray, config: CullingConfig,
                gates: tuple[float, ...] = (8.0, 3.0, 1.0)) -> tuple[np.ndarray, np.ndarray] | None:
    """(rvec, tvec): the predicted pose T_init refined by Levenberg-Marquardt on the points X (N,3) m seen at
    uv (N,2) px that it already explains (once per gate, in multiples of `pnp_px`), or None when most disagree.
    ~10x cheaper than RANSAC, and it converges to the motion of the points near the prediction."""
    rvec, tvec = cv2.Rodrigues(T_init[:3, :3])[0], T_init[:3, 3].reshape(3, 1).copy()
    # the prediction can be several pixels off: refine on a wide gate first, then tighten it
    for gate in gates:
        inl = reprojection_px(X, uv, K, rvec, tvec) < gate * config.pnp_px
        if inl.sum() < max(6, config.min_pose_support * len(X)):
            return None
        rvec, tvec = cv2.solvePnPRefineLM(X[inl], uv[inl], K, None, rvec, tvec)
    support = (reprojection_px(X, uv, K, rvec, tvec) < config.pnp_px).mean()
    return (rvec, tvec) if support >= config.min_pose_support else None


def relative_pose(X: np.ndarray, uv: np.ndarray, K: np.ndarray, T_init: np.ndarray | None,
                  config: CullingConfig, segmented: bool) -> tuple[np.ndarray, np.ndarray] | None:
    """(rvec, tvec) of the current camera from previous-frame points X (N,3) m seen at uv (N,2) px: the
    predicted pose refined (`refine_from`) when there is one and most points agree with it, else PnP-RANSAC's
    when enough agree with that (`min_pose_support`); None: no depth test for this frame."""
    if T_init is not None:
        pose = refine_from(X, uv, K, T_init, config)
        if pose is not None:
            return pose
    got = sqpnp_ransac(X, uv, K, config.pnp_px, 300, 6, config.usac, segmented and config.ap3p_samples)
    if got is None or (segmented and len(got[2]) < config.min_pose_support * len(X)):
        return None
    return got[0], got[1]


def veto_pose(X: np.ndarray, p_cur: np.ndarray, has: np.ndarray, K: np.ndarray, T_init: np.ndarray,
              config: CullingConfig) -> np.ndarray:
    """4x4 T_cur_prev for the prediction veto: the prediction refined on the matched points X (N,3) m that have
    depth (`has`) and are seen at p_cur (N,2) px (the static majority pulls it onto the scene's motion; see
    `refine_prediction_below`), or the prediction itself."""
    idx = spread(np.flatnonzero(has), config.fit_max_points)
    if len(idx) < 6:
        return T_init
    # tight gates: movers within a wide first gate pull the pose along with the scene
    pose = refine_from(X[idx], p_cur[idx].astype(np.float64), K, T_init, config, gates=(3.0, 1.0))
    if pose is None:
        return T_init
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = cv2.Rodrigues(pose[0])[0], pose[1].ravel()
    return T
