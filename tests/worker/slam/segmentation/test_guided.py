"""Guided upsampling of low-resolution class probabilities (synthetic scenes with known truth)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from worker.slam.errors import ConfigError
from worker.slam.presets import get_preset
from worker.slam.segmentation import SegmenterConfig
from worker.slam.segmentation.guided import guided_upsample


def _scene(size: tuple[int, int] = (480, 640)) -> tuple[np.ndarray, np.ndarray]:
    """A textured grey wall with a dark person-like block; returns rgb (H, W, 3) and its true mask (H, W)."""
    h, w = size
    rng = np.random.default_rng(0)
    grey = np.clip(170 + rng.normal(0, 6, size), 0, 255)
    truth = np.zeros(size, bool)
    truth[h // 4: h - 40, 250:390] = True
    grey[truth] = np.clip(60 + rng.normal(0, 6, truth.sum()), 0, 255)
    return np.repeat(grey.astype(np.uint8)[..., None], 3, axis=2), truth


def _coarse_probs(truth: np.ndarray, net_size: tuple[int, int] = (48, 64)) -> np.ndarray:
    """What a low-resolution network gives: the true mask at 1/10 scale, spilling a pixel (10 px at full size)
    over its border and blurred, as (h, w, 2) probabilities."""
    small = cv2.resize(truth.astype(np.float32), net_size[::-1], interpolation=cv2.INTER_AREA)
    small = cv2.dilate(small, np.ones((3, 3), np.uint8))
    person = np.clip(cv2.GaussianBlur(small, (5, 5), 1.5), 0.02, 0.98)
    return np.stack([1 - person, person], -1).astype(np.float32)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def test_mask_borders_follow_image_edges_better_than_bilinear() -> None:
    rgb, truth = _scene()
    probs = _coarse_probs(truth)
    bilinear = cv2.resize(probs, (640, 480), interpolation=cv2.INTER_LINEAR).argmax(-1) == 1
    guided = guided_upsample(probs, rgb, radius=3, eps=1e-3).argmax(-1) == 1
    assert _iou(guided, truth) > _iou(bilinear, truth) + 0.02
    # the errors left are at the border: a few pixels, not blobs
    assert (guided ^ truth).sum() < 0.5 * (bilinear ^ truth).sum()


def test_output_is_a_probability_map_at_full_resolution() -> None:
    rgb, truth = _scene((75, 101))
    probs = np.random.default_rng(1).random((20, 30, 3)).astype(np.float32)
    probs /= probs.sum(-1, keepdims=True)
    q = guided_upsample(probs, rgb, radius=4, eps=1e-4)  # small eps: strong edges make the raw filter overshoot
    assert q.shape == (75, 101, 3) and q.dtype == np.float32
    assert q.min() >= 0 and q.max() <= 1
    np.testing.assert_allclose(q.sum(-1), 1.0, atol=1e-4)
    single = guided_upsample(np.ones((20, 30, 1), np.float32), rgb, radius=4, eps=1e-2)
    assert single.shape == (75, 101, 1)
    np.testing.assert_allclose(single, 1.0, atol=1e-4)


def test_flat_guide_gives_smoothed_bilinear_probabilities() -> None:
    """Without edges in the guide a = 0 and q is the box-smoothed mean (two box passes): nothing is invented."""
    rgb = np.full((96, 128, 3), 128, np.uint8)
    probs = _coarse_probs(_scene((96, 128))[1], (24, 32))
    q = guided_upsample(probs, rgb, radius=2, eps=1e-2)
    box = lambda x: cv2.boxFilter(x, -1, (5, 5), borderType=cv2.BORDER_REFLECT)  # noqa: E731
    expected = cv2.resize(box(box(probs)), (128, 96))
    np.testing.assert_allclose(q, expected, atol=1e-4)


def test_guided_parameters_are_checked() -> None:
    with pytest.raises(ValueError):
        SegmenterConfig(guided_radius=-1)
    with pytest.raises(ValueError):
        SegmenterConfig(guided_eps=0.0)
    with pytest.raises(ConfigError):
        get_preset("no-restoration", {"segmentation": {"segmenter": {"guided_radius": -3}}})
