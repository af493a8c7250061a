"""Search by projection: map points are projected with a predicted pose and matched to nearby keypoints."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.features.search import KeypointIndex, match_near_predictions


@dataclass
class ProjectionMatches:
    """`point_idx` (M,) indices into the candidate points; `kp_idx` (M,) keypoint indices; `visible` (P,)
    bool: candidate projected inside the image within its scale/viewing-angle range."""

    point_idx: np.ndarray
    kp_idx: np.ndarray
    visible: np.ndarray


def search_by_projection(index: KeypointIndex, X_w: np.ndarray, desc: np.ndarray, normal: np.ndarray,
                         max_dist: np.ndarray, T_WC: np.ndarray, K: np.ndarray, size: tuple[int, int],
                         scales: np.ndarray, radius_px: float, max_hamming: int, ratio: float,
                         taken: np.ndarray | None = None) -> ProjectionMatches:
    """Match (P,3) world points `X_w` (descriptors (P,32)) to keypoints of `index` under pose `T_WC`.

    `size` = (width, height). `scales` (levels,) pyramid scales; the search radius grows with the scale
    of the octave the point is predicted at, as in ORB-SLAM2. `taken` (N,) bool marks keypoints already
    matched (skipped). Each keypoint is given to at most one point (the closest descriptor).
    """
    P = len(X_w)
    empty = ProjectionMatches(np.zeros(0, int), np.zeros(0, int), np.zeros(P, bool))
    if P == 0 or index.empty:
        return empty
    R_CW = T_WC[:3, :3].T
    center = T_WC[:3, 3]
    Pc = (X_w - center) @ R_CW.T
    z = Pc[:, 2]
    zs = np.where(z > 1e-3, z, 1.0)
    u = K[0, 0] * Pc[:, 0] / zs + K[0, 2]
    v = K[1, 1] * Pc[:, 1] / zs + K[1, 2]
    w, h = size
    ray = X_w - center
    dist = np.linalg.norm(ray, axis=1)
    min_dist = max_dist / scales[-1]
    cos_view = (ray * normal).sum(1) / np.maximum(dist, 1e-9)
    vis = ((z > 1e-3) & (u >= 0) & (u < w) & (v >= 0) & (v < h) & (dist > 0.8 * min_dist)
           & (dist < 1.2 * max_dist) & (cos_view > 0.5))
    idx = np.flatnonzero(vis)
    if len(idx) == 0:
        return ProjectionMatches(empty.point_idx, empty.kp_idx, vis)
    nl = len(scales)
    level = np.clip(np.ceil(np.log(max_dist[idx] / dist[idx]) / np.log(scales[1] if nl > 1 else 1.2)), 0, nl - 1)
    level = level.astype(int)
    pi, ki = match_near_predictions(index, np.column_stack([u[idx], v[idx]]), desc[idx],
                                    radius_px * scales[level], max_hamming, ratio, level=level, taken=taken)
    return ProjectionMatches(idx[pi], ki, vis)
