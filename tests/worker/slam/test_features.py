"""ORB extraction (pyramid, grid balance, exclude mask), depth lookup and descriptor matching."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from tests.worker.slam.synthetic_room import K_SYN, pose, render
from worker.slam.config import FeatureConfig
from worker.slam.features.depth import backproject, lookup_depth
from worker.slam.features.matching import hamming, match_ratio
from worker.slam.features.orb import OrbExtractor
from worker.slam.features.types import Features


@pytest.fixture(scope="module")
def view():
    rgb, depth = render(pose([0, 0, 0], 10, -15))
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), depth


def test_orb_budget_pyramid_and_grid_balance(view):
    gray, depth = view
    f = OrbExtractor(FeatureConfig(n_features=800)).extract(gray, depth)
    assert 600 <= len(f) <= 800
    assert f.desc.shape == (len(f), 32) and f.desc.dtype == np.uint8
    assert len(np.unique(f.octave)) >= 4  # several pyramid levels
    # grid balance: most 80x80 cells of the image hold keypoints, none holds a large share
    cells = (f.uv[:, 1] // 80).astype(int) * 8 + (f.uv[:, 0] // 80).astype(int)
    counts = np.bincount(cells, minlength=48)
    assert (counts > 0).mean() > 0.9
    assert counts.max() < 0.1 * len(f)


def test_exclude_mask_removes_keypoints(view):
    gray, depth = view
    exclude = np.zeros(gray.shape, bool)
    exclude[:, :320] = True
    f = OrbExtractor(FeatureConfig()).extract(gray, depth, exclude)
    assert len(f) > 200
    assert f.uv[:, 0].min() >= 320 - 1


def test_depth_lookup_matches_rendered_depth(view):
    gray, depth = view
    f = OrbExtractor(FeatureConfig()).extract(gray, depth)
    assert (f.depth > 0).mean() > 0.95
    near = depth[np.rint(f.uv[:, 1]).astype(int), np.rint(f.uv[:, 0]).astype(int)]
    assert np.median(np.abs(f.depth - near) / near) < 0.01


def test_depth_lookup_invalid_and_edges():
    depth = np.zeros((10, 10), np.float32)
    depth[:, 5:] = 2.0
    depth[:, :5] = 1.0
    depth[0, 0] = 0.0
    z = lookup_depth(np.array([[0.0, 0.0], [4.5, 5.0], [7.2, 5.0], [8.0, 8.0]]), depth, 0.1, 1.5)
    assert z[0] == 0  # invalid
    assert z[1] in (1.0, 0.0)  # at the edge: nearest pixel, never an interpolated 1.5
    assert z[2] == 0 and z[3] == 0  # beyond max depth


def test_backproject_roundtrip():
    uv = np.array([[100.0, 50.0], [319.5, 239.5]])
    X = backproject(uv, np.array([2.0, 1.0]), K_SYN)
    proj = X[:, :2] / X[:, 2:] * K_SYN[0, 0] + K_SYN[:2, 2]
    assert np.allclose(proj, uv) and np.allclose(X[:, 2], [2, 1])


def test_hamming_and_ratio_matching():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 256, (50, 32), dtype=np.uint8)
    assert hamming(a, a).sum() == 0
    flipped = a.copy()
    flipped[:, 0] ^= 0b111
    assert (hamming(a, flipped) == 3).all()
    q, t = match_ratio(flipped[::-1], a)
    assert len(q) == 50 and np.array_equal(t, 49 - q)


def test_features_concat_select():
    f = Features(np.zeros((3, 2)), np.arange(3), np.ones(3, np.float32), np.zeros((3, 32), np.uint8),
                 np.ones(3, np.float32))
    g = Features.concat([f, f.select(np.array([True, False, True])), Features.empty()])
    assert len(g) == 5 and list(g.octave) == [0, 1, 2, 0, 2]
