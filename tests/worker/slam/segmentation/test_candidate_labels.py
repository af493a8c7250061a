"""Labels of a many-class network from the classes that win a grid cell: the full argmax, at a fraction of the
upsampling."""
from __future__ import annotations

import cv2
import numpy as np

from worker.slam.segmentation.base import labels_of
from worker.slam.segmentation.msnet.segmenter import candidate_labels


def _probs(rng: np.random.Generator, k: int = 21, h: int = 24, w: int = 32) -> np.ndarray:
    """Smooth blobs of a few classes over a background, as a trained network's probabilities look."""
    logits = rng.normal(0, 0.3, (h, w, k)).astype(np.float32)
    logits[..., 0] += 2.0
    yy, xx = np.mgrid[0:h, 0:w]
    for c in rng.choice(np.arange(1, k), 4, replace=False):
        cy, cx, r = rng.uniform(0, h), rng.uniform(0, w), rng.uniform(3, 9)
        logits[..., c] += 5.0 * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * r * r))
    p = np.exp(logits - logits.max(-1, keepdims=True))
    return (p / p.sum(-1, keepdims=True)).astype(np.float32)


def test_candidate_labels_match_the_full_argmax() -> None:
    rng = np.random.default_rng(0)
    for _ in range(10):
        small = _probs(rng)
        full = labels_of(cv2.resize(small, (160, 120), interpolation=cv2.INTER_LINEAR))
        fast = candidate_labels(small, (120, 160))
        assert fast.dtype == np.uint8 and fast.shape == (120, 160)
        assert (fast != full).mean() < 1e-3


def test_one_winning_class_fills_the_frame() -> None:
    small = np.zeros((6, 8, 21), np.float32)
    small[..., 9] = 1.0
    assert (candidate_labels(small, (30, 40)) == 9).all()
