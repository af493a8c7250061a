"""PnP-RANSAC from 3D points to 2D keypoints (relocalisation and loop closure; SQPnP for frame-to-frame poses)."""
from __future__ import annotations

import cv2
import numpy as np


def pnp_ransac(X_w: np.ndarray, uv: np.ndarray, K: np.ndarray, reproj_px: float = 4.0,
               iterations: int = 200, confidence: float = 0.99) -> tuple[np.ndarray, np.ndarray] | None:
    """T_WC (4x4) and (N,) bool inliers from (N,3) world points and their (N,2) pixels; None if it fails."""
    if len(X_w) < 6:
        return None
    ok, rvec, tvec, inl = cv2.solvePnPRansac(
        X_w.astype(np.float64), uv.astype(np.float64), K, None, iterationsCount=iterations,
        reprojectionError=reproj_px, confidence=confidence, flags=cv2.SOLVEPNP_EPNP)
    if not ok or inl is None or len(inl) < 6:
        return None
    R, _ = cv2.Rodrigues(rvec)
    T_CW = np.eye(4)
    T_CW[:3, :3], T_CW[:3, 3] = R, tvec.ravel()
    mask = np.zeros(len(X_w), bool)
    mask[inl.ravel()] = True
    T_WC = np.eye(4)
    T_WC[:3, :3] = R.T
    T_WC[:3, 3] = -R.T @ tvec.ravel()
    return T_WC, mask


def reprojection_px(X: np.ndarray, uv: np.ndarray, K: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """(N,) pixel distance between points `X` (N,3) projected by the pose (rvec, tvec) and their keypoints `uv`
    (N,2) px (no distortion)."""
    return np.linalg.norm(cv2.projectPoints(X, rvec, tvec, K, None)[0].reshape(-1, 2) - uv, axis=1)


def sqpnp_ransac(X: np.ndarray, uv: np.ndarray, K: np.ndarray, reproj_px: float, iterations: int,
                 min_inliers: int, usac: bool = False,
                 ap3p_samples: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(rvec, tvec, inlier indices) of the camera seeing (N,3) points `X` at (N,2) float64 pixels `uv`, by
    SQPnP-RANSAC (EPnP degenerates on planar scenes); None when it fails or keeps fewer than `min_inliers`.
    SQPnP asserts on a sample whose points (nearly) coincide (seen on real frames): that is a failure too.
    `usac`: OpenCV's USAC instead (P3P samples, local optimisation, SQPnP-free), far fewer hypotheses when
    most points are outliers. `ap3p_samples`: the hypotheses by AP3P on 4 points (a third of the cost per
    hypothesis in OpenCV's loop), then SQPnP on their consensus and the inliers of that fit (OpenCV would refit
    a P3P consensus by EPnP)."""
    flags = cv2.USAC_DEFAULT if usac else cv2.SOLVEPNP_AP3P if ap3p_samples else cv2.SOLVEPNP_SQPNP
    try:
        ok, rvec, tvec, inl = cv2.solvePnPRansac(X, uv, K, None, reprojectionError=reproj_px,
                                                 iterationsCount=iterations, flags=flags)
        if ok and inl is not None and len(inl) >= min_inliers and flags == cv2.SOLVEPNP_AP3P:
            ok, rvec, tvec = cv2.solvePnP(X[inl.ravel()], uv[inl.ravel()], K, None, flags=cv2.SOLVEPNP_SQPNP)
            inl = np.flatnonzero(reprojection_px(X, uv, K, rvec, tvec) < reproj_px)
    except cv2.error:
        return None
    if not ok or inl is None or len(inl) < min_inliers:
        return None
    return rvec, tvec, inl.ravel()
