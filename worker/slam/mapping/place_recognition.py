"""Descriptor-based place recognition: bag-of-binary-words vectors of keyframes and their similarity.

The vocabulary is learnt online from the first keyframes of the sequence (their ORB descriptors, sampled),
so nothing has to be trained or shipped; each descriptor votes for its nearest word (Hamming) and
keyframes are compared with DBoW2's L1 score s = 1 - |a - b|_1 / 2 on L1-normalised word histograms.
"""
from __future__ import annotations

import cv2
import numpy as np

VOCAB_KEYFRAMES = 5
VOCAB_WORDS = 1000


class PlaceRecognizer:
    def __init__(self, descriptors_per_keyframe: int, seed: int = 0) -> None:
        self.per_kf = descriptors_per_keyframe
        self.rng = np.random.default_rng(seed)
        self.vocab: np.ndarray | None = None
        self.pending: list[np.ndarray] = []  # descriptors of keyframes seen before the vocabulary exists
        self.bows = np.zeros((0, VOCAB_WORDS), np.float32)
        self._matcher = cv2.BFMatcher(cv2.NORM_HAMMING)

    def _strongest(self, desc: np.ndarray, response: np.ndarray) -> np.ndarray:
        return desc[np.argsort(-response)[: self.per_kf]]

    def add(self, desc: np.ndarray, response: np.ndarray) -> None:
        """Add the next keyframe's (N,32) uint8 descriptors (ids follow insertion order)."""
        d = self._strongest(desc, response)
        if self.vocab is None:
            self.pending.append(d)
            if len(self.pending) >= VOCAB_KEYFRAMES:
                pool = np.vstack(self.pending)
                pick = self.rng.choice(len(pool), size=min(VOCAB_WORDS, len(pool)), replace=False)
                self.vocab = np.ascontiguousarray(pool[pick])
                self.bows = np.vstack([self._bow(p) for p in self.pending])
                self.pending = []
            return
        self.bows = np.vstack([self.bows, self._bow(d)])

    def _bow(self, d: np.ndarray) -> np.ndarray:
        v = np.zeros(VOCAB_WORDS, np.float32)
        if len(d):
            words = np.array([m.trainIdx for m in self._matcher.match(d, self.vocab)])
            np.add.at(v, words, 1.0)
            v /= v.sum()
        return v[None]

    def scores(self, kf_id: int) -> np.ndarray:
        """(n_keyframes,) similarity of keyframe `kf_id` to every keyframe (0..1); zeros before the vocabulary."""
        if self.vocab is None or kf_id >= len(self.bows):
            return np.zeros(max(len(self.bows), kf_id + 1))
        return 1.0 - 0.5 * np.abs(self.bows - self.bows[kf_id]).sum(1)
