"""A vocabulary tree of binary ORB words (DBoW2's model) and tf-idf bag-of-words vectors of images.

The tree is trained offline (`worker.slam.vocab_train`, `vtdslam train-vocab`) by hierarchical k-majority
clustering in Hamming space and shipped with the package (`features/data/`, see its VOCABULARY.md card).
A descriptor descends from the root to the child whose centre is nearest in Hamming distance until it reaches
a leaf: that leaf is its word. An image's vector weighs each word by tf (its share of the image's descriptors)
times idf (log of the training images over those containing the word), L1-normalised as in ORB-SLAM2, so that
DBoW2's L1 score of two vectors is the sum over their common words of the smaller weight.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: The shipped vocabulary (k=10, L=4), trained by `vtdslam train-vocab` (see data/VOCABULARY.md).
DEFAULT_VOCABULARY = Path(__file__).with_name("data") / "orb_vocab_k10l4.npz"


@dataclass(frozen=True)
class BowVector:
    """Sparse tf-idf vector: sorted word ids (int32) and their L1-normalised weights (float32)."""

    words: np.ndarray
    weights: np.ndarray

    def score(self, other: BowVector) -> float:
        """DBoW2's L1 score in [0, 1]: 1 - |a - b|_1 / 2, i.e. the sum of min(a, b) over common words."""
        _, ia, ib = np.intersect1d(self.words, other.words, assume_unique=True, return_indices=True)
        return float(np.minimum(self.weights[ia], other.weights[ib]).sum())


@dataclass(frozen=True)
class Vocabulary:
    """A k-ary tree of binary words. Node 0 is the root; `children[n]` (k,) are node ids, -1 where absent;
    `word_of[n]` the word id of a leaf node (-1 for inner nodes); `idf` (W,) the words' weights."""

    centres: np.ndarray  # (M, 32) uint8 node centres (the root's is unused)
    children: np.ndarray  # (M, k) int32
    word_of: np.ndarray  # (M,) int32
    idf: np.ndarray  # (W,) float32
    depth: np.ndarray  # (M,) int8, the root at 0

    @property
    def k(self) -> int:
        return int(self.children.shape[1])

    @property
    def levels(self) -> int:
        return int(self.depth.max())

    @property
    def n_words(self) -> int:
        return len(self.idf)

    @classmethod
    def load(cls, path: Path | str = DEFAULT_VOCABULARY) -> Vocabulary:
        with np.load(path) as z:
            return cls(z["centres"], z["children"], z["word_of"], z["idf"], z["depth"])

    def save(self, path: Path | str) -> None:
        np.savez_compressed(path, centres=self.centres, children=self.children, word_of=self.word_of,
                            idf=self.idf, depth=self.depth)

    def descend(self, desc: np.ndarray, stop_depth: int | None = None) -> np.ndarray:
        """(N,) node id each (N,32) uint8 descriptor reaches: its leaf, or its node at `stop_depth`."""
        return self.descend_both(desc, 0 if stop_depth is None else stop_depth, stop_depth)[0]

    def descend_both(self, desc: np.ndarray, mid_depth: int, stop_depth: int | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
        """((N,) leaf or node at `stop_depth`, (N,) node at `mid_depth`) of (N,32) uint8 descriptors, in one
        descent (the second is the direct index's node)."""
        node = np.zeros(len(desc), np.int64)
        mid = node
        desc = np.ascontiguousarray(desc, np.uint8).view(np.uint64)  # 4 words per ORB descriptor
        centres = self.centres.view(np.uint64)
        last = self.levels if stop_depth is None else stop_depth
        for level in range(last):
            ch = self.children[node]  # (N, k)
            valid = ch >= 0
            inner = valid.any(1)
            if not inner.any():
                break
            dist = np.bitwise_count(desc[:, None, :] ^ centres[np.maximum(ch, 0)]).sum(-1, dtype=np.int32)
            dist[~valid] = 1 << 20
            best = ch[np.arange(len(ch)), dist.argmin(1)]
            node = np.where(inner, best, node)
            if level + 1 == mid_depth:
                mid = node
        return node, mid

    def words(self, desc: np.ndarray) -> np.ndarray:
        """(N,) word id of each (N,32) uint8 descriptor."""
        return self.word_of[self.descend(desc)]

    def bow(self, desc: np.ndarray) -> BowVector:
        """tf-idf vector of one image's (N,32) uint8 descriptors (empty for none)."""
        if len(desc) == 0:
            return BowVector(np.zeros(0, np.int32), np.zeros(0, np.float32))
        return self.bow_of_words(self.words(desc))

    def bow_of_words(self, words: np.ndarray) -> BowVector:
        """tf-idf vector from the (N,) word ids of one image's descriptors."""
        ids, counts = np.unique(words, return_counts=True)
        w = counts / len(words) * self.idf[ids]
        keep = w > 0  # words present in every training image carry no information
        ids, w = ids[keep], w[keep]
        total = w.sum()
        return BowVector(ids.astype(np.int32), (w / total if total > 0 else w).astype(np.float32))
