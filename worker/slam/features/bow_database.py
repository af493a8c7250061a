"""Keyframe database: the keyframes' bag-of-words vectors, an inverted file and a direct index (DBoW2's).

The inverted file (word -> keyframes that contain it, kept as a sparse keyframe x word matrix) scores a query
against every keyframe at once with DBoW2's L1 score and counts the words they share; the direct index (per
keyframe, the tree node of each descriptor a few levels below the root) restricts descriptor matching between
two images to descriptors that fall under the same node, as ORB-SLAM2's SearchByBoW does.
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import scipy.sparse as sp

from worker.slam.features.vocabulary import BowVector, Vocabulary


class KeyframeDatabase:
    """Keyframes are added in id order (0, 1, ...), each with its (N,32) uint8 descriptors."""

    def __init__(self, vocab: Vocabulary, direct_depth: int = 2) -> None:
        self.vocab = vocab
        self.direct_depth = min(direct_depth, vocab.levels)
        self.bows: list[BowVector] = []
        self.nodes: list[np.ndarray] = []  # per keyframe (N,) direct-index node of each descriptor
        self._matrix: sp.csc_matrix | None = None

    def __len__(self) -> int:
        return len(self.bows)

    def add(self, desc: np.ndarray) -> int:
        """Index the next keyframe's descriptors; returns its id."""
        bow, nodes = self.transform(desc)
        self.bows.append(bow)
        self.nodes.append(nodes)
        self._matrix = None
        return len(self.bows) - 1

    def extend(self, descs: Iterable[np.ndarray]) -> None:
        """Index the next keyframes' descriptors, in id order."""
        for d in descs:
            self.add(d)

    def transform(self, desc: np.ndarray) -> tuple[BowVector, np.ndarray]:
        """(tf-idf vector, (N,) direct-index node per descriptor) of an image's (N,32) uint8 descriptors."""
        if len(desc) == 0:
            return self.vocab.bow(desc), np.zeros(0, np.int64)
        leaf, node = self.vocab.descend_both(desc, self.direct_depth)  # node: the leaf's ancestor at that depth
        return self.vocab.bow_of_words(self.vocab.word_of[leaf]), node

    def _csc(self) -> sp.csc_matrix:
        """The keyframe x word matrix (the inverted file), rebuilt after keyframes were added."""
        if self._matrix is None:
            n = len(self.bows)
            rows = np.repeat(np.arange(n), [len(b.words) for b in self.bows])
            cols = np.concatenate([b.words for b in self.bows]) if n else np.zeros(0, np.int32)
            vals = np.concatenate([b.weights for b in self.bows]) if n else np.zeros(0, np.float32)
            self._matrix = sp.csc_matrix((vals, (rows, cols)), shape=(n, self.vocab.n_words), dtype=np.float32)
        return self._matrix

    def query(self, bow: BowVector, upto: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(scores, common word counts), each (n,) over keyframes 0..n-1 (n = `upto` or all)."""
        M = self._csc()
        n = M.shape[0] if upto is None else min(upto, M.shape[0])
        if n == 0 or len(bow.words) == 0:
            return np.zeros(n), np.zeros(n, int)
        sub = M[:n][:, bow.words].toarray()  # (n, words of the query)
        return np.minimum(sub, bow.weights[None]).sum(1).astype(np.float64), (sub > 0).sum(1)

    def match(self, kf_a: int | None, desc_a: np.ndarray, kf_b: int, desc_b: np.ndarray, ratio: float = 0.75,
              max_dist: int = 50, candidates_b: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Matches (ia, ib) of descriptors `desc_a` (keyframe `kf_a`, or a frame when None) to keyframe `kf_b`'s
        `desc_b`, compared only under the same direct-index node; `candidates_b` bool (N_b,) limits b's side.
        Ratio test against the second best in the node, one match per b (the closest)."""
        nodes_a = self.nodes[kf_a] if kf_a is not None else self.transform(desc_a)[1]
        nodes_b = self.nodes[kf_b]
        ok_b = np.ones(len(desc_b), bool) if candidates_b is None else candidates_b
        a64 = np.ascontiguousarray(desc_a, np.uint8).view(np.uint64)
        b64 = np.ascontiguousarray(desc_b, np.uint8).view(np.uint64)
        ia_all, ib_all, d_all = [], [], []
        for node in np.intersect1d(nodes_a, nodes_b[ok_b]):
            ia = np.flatnonzero(nodes_a == node)
            ib = np.flatnonzero((nodes_b == node) & ok_b)
            d = np.bitwise_count(a64[ia, None, :] ^ b64[None, ib, :]).sum(-1, dtype=np.int32)  # (na, nb)
            best = d.argmin(1)
            d1 = d[np.arange(len(ia)), best]
            d2 = np.partition(d, 1, axis=1)[:, 1] if len(ib) > 1 else np.full(len(ia), 1 << 10)
            good = (d1 <= max_dist) & (d1 < ratio * d2)
            ia_all.append(ia[good])
            ib_all.append(ib[best[good]])
            d_all.append(d1[good])
        if not ia_all:
            return np.zeros(0, int), np.zeros(0, int)
        ia, ib, dd = np.concatenate(ia_all), np.concatenate(ib_all), np.concatenate(d_all)
        order = np.lexsort((dd, ib))  # one a per b: the closest
        ia, ib = ia[order], ib[order]
        first = np.r_[True, ib[1:] != ib[:-1]] if len(ib) else np.zeros(0, bool)
        return ia[first], ib[first]
