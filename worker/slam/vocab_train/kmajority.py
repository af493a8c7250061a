"""k-majority clustering of binary descriptors (k-means in Hamming space, DBoW2's k-medians for binary words).

Seeding is k-means++ (DBoW2's): each next centre is drawn with probability proportional to the squared Hamming
distance to the nearest centre so far. A centre is then the bitwise majority of its members (the binary
median that minimises their summed Hamming distance, ties to 0), and members go to their nearest centre,
until no assignment changes.
"""
from __future__ import annotations

import numpy as np


def distances(data: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(N, C) int32 Hamming distances of (N, W) uint64 descriptors to (C, W) uint64 centres."""
    return np.bitwise_count(data[:, None, :] ^ centres[None, :, :]).sum(-1, dtype=np.int32)


def seed_plus_plus(data: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """(k', W) uint64 initial centres (k' <= k: fewer when the data has fewer distinct descriptors)."""
    centres = [data[rng.integers(len(data))]]
    nearest = distances(data, centres[0][None])[:, 0].astype(np.float64)
    while len(centres) < k:
        p = nearest**2
        if p.sum() == 0:  # every descriptor equals a centre
            break
        c = data[rng.choice(len(data), p=p / p.sum())]
        centres.append(c)
        nearest = np.minimum(nearest, distances(data, c[None])[:, 0])
    return np.stack(centres)


def majority(bits: np.ndarray, labels: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Per cluster, the bitwise majority of its members' (N, B) uint8 0/1 `bits`: ((k, B/8) uint8 packed
    centres, (k,) member counts)."""
    counts = np.bincount(labels, minlength=k)
    order = np.argsort(labels, kind="stable")
    present = np.flatnonzero(counts)
    sums = np.zeros((k, bits.shape[1]), np.int64)
    starts = np.r_[0, np.cumsum(counts[present])[:-1]]
    sums[present] = np.add.reduceat(bits[order].astype(np.int32), starts, axis=0)
    return np.packbits((2 * sums > counts[:, None]).astype(np.uint8), axis=1), counts


def kmajority(desc: np.ndarray, k: int, rng: np.random.Generator, max_iter: int = 15
              ) -> tuple[np.ndarray, np.ndarray]:
    """Cluster (N, 32) uint8 descriptors: ((C, 32) uint8 centres, (N,) labels in 0..C-1), C <= k, none empty."""
    data = np.ascontiguousarray(desc, np.uint8).view(np.uint64)
    bits = np.unpackbits(desc, axis=1)
    centres = seed_plus_plus(data, k, rng)
    labels = distances(data, centres).argmin(1)
    for _ in range(max_iter):
        packed, counts = majority(bits, labels, len(centres))
        packed = packed[counts > 0]  # an emptied cluster disappears
        centres = np.ascontiguousarray(packed).view(np.uint64)
        new = distances(data, centres).argmin(1)
        if np.array_equal(new, labels):
            break
        labels = new
    packed, counts = majority(bits, labels, len(centres))
    keep = counts > 0
    remap = np.cumsum(keep) - 1
    return packed[keep], remap[labels]
