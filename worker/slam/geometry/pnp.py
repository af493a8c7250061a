"""PnP-RANSAC from 3D map points to 2D keypoints (initialisation for relocalisation and loop closure)."""
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
