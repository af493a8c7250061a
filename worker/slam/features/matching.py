"""Descriptor distances and brute-force matching of binary (ORB) descriptors."""
from __future__ import annotations

import cv2
import numpy as np


def hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise Hamming distance of uint8 descriptors `a`, `b` (..., 32) -> (...) int."""
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    if a.shape[-1] % 8 == 0:  # as 64-bit words: 8x fewer elements to xor and count (ORB: 4 per descriptor)
        a, b = a.view(np.uint64), b.view(np.uint64)
    return np.bitwise_count(np.bitwise_xor(a, b)).sum(axis=-1, dtype=np.int32)


def match_ratio(desc_q: np.ndarray, desc_t: np.ndarray, ratio: float = 0.8,
                max_dist: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """Brute-force 2-NN matching with Lowe's ratio test and one-to-one targets.

    Returns (query indices, target indices), both (M,) int.
    """
    if len(desc_q) < 2 or len(desc_t) < 2:
        return np.zeros(0, int), np.zeros(0, int)
    knn = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(desc_q, desc_t, k=2)
    good = [m[0] for m in knn if len(m) == 2 and m[0].distance <= max_dist and m[0].distance < ratio * m[1].distance]
    if not good:
        return np.zeros(0, int), np.zeros(0, int)
    q = np.array([m.queryIdx for m in good])
    t = np.array([m.trainIdx for m in good])
    d = np.array([m.distance for m in good])
    order = np.argsort(d)
    _, first = np.unique(t[order], return_index=True)  # keep the closest query per target
    keep = order[first]
    return q[keep], t[keep]
