"""Matches between consecutive frames, the fundamental matrix from static matches, epipolar distances."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class Matches:
    """Indices into the previous (`prev_idx`) and current (`cur_idx`) keypoint arrays, (N,) each."""

    prev_idx: np.ndarray
    cur_idx: np.ndarray


def match_orb(desc_prev: np.ndarray, desc_cur: np.ndarray, max_distance: int = 50) -> Matches:
    """Cross-checked Hamming matches of ORB descriptors (N, 32) uint8."""
    if desc_prev is None or desc_cur is None or len(desc_prev) == 0 or len(desc_cur) == 0:
        return Matches(np.zeros(0, int), np.zeros(0, int))
    ms = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(desc_prev, desc_cur)
    ms = [m for m in ms if m.distance <= max_distance]
    return Matches(np.array([m.queryIdx for m in ms], int), np.array([m.trainIdx for m in ms], int))


def fundamental_ransac(p_prev: np.ndarray, p_cur: np.ndarray, threshold_px: float = 1.0,
                       confidence: float = 0.999) -> np.ndarray | None:
    """F (3x3) with x_cur^T F x_prev = 0 from pixel points (N, 2), RANSAC over eight-point solutions."""
    if len(p_prev) < 8:
        return None
    F, _ = cv2.findFundamentalMat(p_prev.astype(np.float64), p_cur.astype(np.float64), cv2.FM_RANSAC,
                                  threshold_px, confidence)
    if F is None or F.shape != (3, 3):
        return None
    return F


def epipolar_distance(F: np.ndarray, p_prev: np.ndarray, p_cur: np.ndarray) -> np.ndarray:
    """Distance (N,) in pixels of each current point to the epipolar line F x_prev of its match."""
    ones = np.ones((len(p_prev), 1))
    lines = np.hstack([p_prev, ones]) @ F.T  # (a, b, c) per match, in the current image
    num = np.abs(np.sum(lines * np.hstack([p_cur, ones]), axis=1))
    return num / np.maximum(np.hypot(lines[:, 0], lines[:, 1]), 1e-12)
