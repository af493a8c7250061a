"""Descriptor distances and brute-force matching of binary (ORB) descriptors."""
from __future__ import annotations

import cv2
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic


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


def cross_checked(desc_a: np.ndarray, desc_b: np.ndarray, max_distance: int) -> tuple[np.ndarray, np.ndarray]:
    """Mutual nearest neighbours of binary descriptors `desc_a` (N, 32) and `desc_b` (M, 32) uint8 in Hamming
    distance, kept when at most `max_distance`: (indices into a, indices into b), (K,) int each, in a's order.

    The same matches as OpenCV's cross-checked `BFMatcher(NORM_HAMMING)` (ties go to the lowest index both
    ways), ~7x faster: one pass over the N x M pairs with the CPU's popcount, no distance matrix, no Python
    objects per match (culling's objects and restoration's references called it on hundreds x hundreds)."""
    if len(desc_a) == 0 or len(desc_b) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    a, b = as_words(desc_a), as_words(desc_b)
    return _cross_checked(a, b, max_distance)


def as_words(desc: np.ndarray) -> np.ndarray:
    """(N, bytes) uint8 descriptors as (N, bytes / 8) uint64 words (zero-padded to a multiple of 8 bytes)."""
    desc = np.ascontiguousarray(desc, np.uint8)
    pad = -desc.shape[1] % 8
    if pad:
        desc = np.ascontiguousarray(np.pad(desc, ((0, 0), (0, pad))))
    return desc.view(np.uint64)


@intrinsic
def popcount64(typingctx, x):
    """LLVM's ctpop: one POPCNT instruction (numba has no bit count of its own)."""
    def codegen(context, builder, signature, args):
        return builder.call(builder.module.declare_intrinsic("llvm.ctpop", [ir.IntType(64)]), args)
    return types.uint64(types.uint64), codegen


@njit(cache=True, nogil=True)
def _cross_checked(a, b, max_distance):
    # Row by row: the distances of a[i] to every b[j] first (b's words transposed so each pass streams one
    # word of all b: the loops vectorise), then the row's first minimum and the columns' running minima
    # (strict: the first of equal distances wins both ways, as in OpenCV). int32 lanes: twice the width.
    n, m, words = a.shape[0], b.shape[0], a.shape[1]
    row_best = np.empty(n, np.int64)
    row_dist = np.empty(n, np.int64)
    col_best = np.zeros(m, np.int32)
    col_dist = np.full(m, 1 << 30, np.int32)
    bt = np.ascontiguousarray(b.T)
    d = np.empty(m, np.int32)
    for i in range(n):
        a0 = a[i, 0]
        for j in range(m):
            d[j] = np.int32(popcount64(a0 ^ bt[0, j]))
        for k in range(1, words):
            ak = a[i, k]
            for j in range(m):
                d[j] += np.int32(popcount64(ak ^ bt[k, j]))
        best_d = np.int32(1 << 30)
        for j in range(m):
            best_d = min(best_d, d[j])
        best = 0
        while d[best] != best_d:
            best += 1
        row_i = np.int32(i)
        for j in range(m):
            better = d[j] < col_dist[j]
            col_dist[j] = d[j] if better else col_dist[j]
            col_best[j] = row_i if better else col_best[j]
        row_best[i], row_dist[i] = best, best_d
    keep = np.zeros(n, np.bool_)
    for i in range(n):
        keep[i] = col_best[row_best[i]] == i and row_dist[i] <= max_distance
    idx = np.flatnonzero(keep)
    return idx, row_best[idx]
