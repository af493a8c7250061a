"""Keypoint search near predicted positions: a spatial index over one frame's keypoints and descriptor matching
among the few nearest to each prediction (the core of ORB-SLAM2's search by projection)."""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from worker.slam.features.grid import PointGrid
from worker.slam.features.matching import as_words, popcount64
from worker.slam.features.types import Features

K_NEAREST = 8


class KeypointIndex:
    """A spatial index over one frame's keypoints, built once per frame and reused by every search.

    Two kinds that find the same K nearest and differ only in the order of equal distances (common: keypoints
    on integer positions, one position at several octaves): a k-d tree (the tracker's; its trajectories are
    compared byte for byte across versions, and a new order of ties moved 7-Scenes' 1000-frame ATE by 4 %)
    and, with `grid`, a compiled grid (`PointGrid`: under half the tree's cost on a thousand keypoints; culling
    builds and queries two or three per frame)."""

    def __init__(self, feats: Features, grid: bool = False) -> None:
        self.feats = feats
        self.tree = cKDTree(feats.uv) if len(feats) and not grid else None
        self.grid = PointGrid.of(feats.uv) if len(feats) and grid else None

    @classmethod
    def of_points(cls, uv: np.ndarray, desc: np.ndarray, grid: bool = False) -> KeypointIndex:
        """An index over bare keypoints (N,2) px with descriptors (N,32), any octave."""
        n = len(uv)
        return cls(Features(np.asarray(uv, np.float64), np.zeros(n, int), np.zeros(n, np.float32), desc,
                            np.zeros(n, np.float32)), grid)

    @property
    def empty(self) -> bool:
        return self.tree is None and self.grid is None

    def nearest(self, uv: np.ndarray, radius: np.ndarray, k: int) -> np.ndarray:
        """(P, k) int: the k keypoints nearest to each point `uv` (P, 2) px within its `radius` (P,), nearest
        first, -1 where fewer are that near (the index must not be `empty`)."""
        if self.grid is not None:
            return self.grid.nearest(uv, radius, k)
        assert self.tree is not None
        d, cand = self.tree.query(uv, k=k, distance_upper_bound=float(radius.max()))
        d, cand = d.reshape(len(uv), k), cand.reshape(len(uv), k)
        return np.where((cand < len(self.feats)) & (d <= radius[:, None]), cand, -1)


def match_near_predictions(index: KeypointIndex, uv_pred: np.ndarray, desc: np.ndarray, radius: np.ndarray,
                           max_hamming: int, ratio: float, level: np.ndarray | None = None,
                           taken: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Match P predicted positions `uv_pred` (P,2) px with descriptors `desc` (P,32) to the keypoints of
    `index` within `radius` (P,) px: the closest descriptor among the K_NEAREST nearest keypoints, Lowe's
    `ratio` against the second, at most `max_hamming`; keypoint octave within ±1 of `level` (P,) when given.
    Each keypoint goes to at most one prediction. Returns (prediction indices, keypoint indices), (M,) each.
    """
    feats = index.feats
    if len(uv_pred) == 0 or index.empty:
        return np.zeros(0, int), np.zeros(0, int)
    cand = index.nearest(uv_pred, radius, min(K_NEAREST, len(feats)))
    ok = cand >= 0
    cand_c = np.where(ok, cand, 0)
    if level is not None:
        oct_ = feats.octave[cand_c]
        ok &= (oct_ >= level[:, None] - 1) & (oct_ <= level[:, None] + 1)
    if taken is not None:
        ok &= ~taken[cand_c]
    return _best_matches(ok, cand_c, as_words(desc), as_words(feats.desc), len(feats), max_hamming, ratio)


@njit(cache=True, nogil=True)
def _best_matches(ok, cand, desc, feat_desc, n_feats, max_hamming, ratio):
    """Per prediction p, the candidate keypoint `cand[p]` (P, k) allowed by `ok` with the least Hamming distance
    of descriptor words `desc[p]` to `feat_desc`, kept when at most `max_hamming` and below `ratio` x the second
    least (a tie at the least fails that test); then each keypoint keeps its closest prediction (the first of
    equals). Returns (prediction indices, keypoint indices) ordered by keypoint."""
    P, k = cand.shape
    words = desc.shape[1]
    kp_pred = np.full(n_feats, -1, np.int64)
    kp_dist = np.zeros(n_feats, np.int64)
    for p in range(P):
        best, second, best_kp = 10_000, 10_000, -1
        for j in range(k):
            if not ok[p, j]:
                continue
            c = cand[p, j]
            d = 0
            for w in range(words):
                d += popcount64(desc[p, w] ^ feat_desc[c, w])
            if d < best:
                best, second, best_kp = d, best, c
            elif d < second:
                second = d
        if best_kp < 0 or best > max_hamming or not (second >= 10_000 or best < ratio * second):
            continue
        if kp_pred[best_kp] < 0 or best < kp_dist[best_kp]:
            kp_pred[best_kp], kp_dist[best_kp] = p, best
    ki = np.flatnonzero(kp_pred >= 0)
    return kp_pred[ki], ki
