"""ORB extraction (pyramid, grid balance, exclude mask), depth lookup and descriptor matching."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from tests.worker.slam.synthetic_room import K_SYN, pose, render
from worker.slam.config import FeatureConfig
from worker.slam.features.depth import backproject, lookup_depth
from worker.slam.features.grid import PointGrid
from worker.slam.features.matching import cross_checked, hamming, match_ratio
from worker.slam.features.orb import OrbExtractor
from worker.slam.features.search import KeypointIndex, match_near_predictions
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


def test_overdetection_leaves_a_plain_scene_its_share_beside_a_textured_object(shared):
    """A real 7-Scenes frame with a high-contrast texture (a patterned shirt, say) pasted over the middle quarter:
    ORB keeps the strongest `overdetect x n_features` corners before the grid spreads them, so at 3 (the
    default) the texture took 58 % of the budget and the room 424 keypoints; at 6, 568; at 1, 143."""
    root = shared / "data" / "7scenes_redkitchen"
    name = [ln for ln in (root / "rgb.txt").read_text().splitlines() if not ln.startswith("#")][60].split()[1]
    gray = cv2.cvtColor(cv2.imread(str(root / name)), cv2.COLOR_BGR2GRAY)
    noise = (np.random.default_rng(0).random((60, 80)) > 0.5).astype(np.uint8) * 255
    gray[120:360, 160:480] = cv2.resize(noise, (320, 240), interpolation=cv2.INTER_NEAREST)

    def outside(overdetect: int) -> int:
        uv = OrbExtractor(FeatureConfig(overdetect=overdetect)).extract(gray).uv
        return int((~((uv[:, 0] >= 160) & (uv[:, 0] < 480) & (uv[:, 1] >= 120) & (uv[:, 1] < 360))).sum())

    assert outside(6) > 0.5 * FeatureConfig().n_features
    assert outside(6) > 1.2 * outside(3) > 2 * outside(1)


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


def _opencv_cross_checked(a: np.ndarray, b: np.ndarray, max_distance: int) -> tuple[np.ndarray, np.ndarray]:
    ms = [m for m in cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(a, b) if m.distance <= max_distance]
    return np.array([m.queryIdx for m in ms], int), np.array([m.trainIdx for m in ms], int)


@pytest.mark.parametrize("n,m,bits", [(300, 200, 32), (37, 400, 32), (120, 90, 20), (150, 100, 1), (1, 1, 32)])
def test_cross_checked_equals_opencv(n, m, bits):
    """The numba matcher gives OpenCV's cross-checked matches, ties included: half of b are noisy copies of a,
    the rest random; short descriptors (`bits` bytes, padded to words; one byte: ties everywhere)."""
    rng = np.random.default_rng(n + m)
    a = rng.integers(0, 256, (n, bits), dtype=np.uint8)
    b = rng.integers(0, 256, (m, bits), dtype=np.uint8)
    k = min(n, m) // 2
    b[:k] = a[:k] ^ (rng.random((k, bits)) < 0.04).astype(np.uint8)
    for max_distance in (0, 30, 256):
        got, want = cross_checked(a, b, max_distance), _opencv_cross_checked(a, b, max_distance)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    assert all(len(x) == 0 for x in cross_checked(a[:0], b, 50))


def test_cross_checked_on_real_orb(view):
    """Real ORB descriptors of two views of the synthetic room: the same matches as OpenCV."""
    ext = OrbExtractor(FeatureConfig())
    f0 = ext.extract(*view)
    rgb1, depth1 = render(pose([0.05, 0, 0], 13, -15))
    f1 = ext.extract(cv2.cvtColor(rgb1, cv2.COLOR_RGB2GRAY), depth1)
    got, want = cross_checked(f0.desc, f1.desc, 50), _opencv_cross_checked(f0.desc, f1.desc, 50)
    assert len(got[0]) > 100 and np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def _reference_near_predictions(feats, uv_pred, desc, radius, max_hamming, ratio, level, taken):
    """The search written plainly: the K nearest keypoints within the radius, then the rules."""
    k = min(8, len(feats))
    best = {}
    for p in range(len(uv_pred)):
        dist = []
        for c in _plain_nearest(feats.uv, uv_pred[p], radius[p], k):
            if taken[c] or abs(feats.octave[c] - level[p]) > 1:
                continue
            dist.append((int(hamming(desc[p], feats.desc[c])), c))
        if not dist:
            continue
        values = sorted(v for v, _ in dist)
        first = min(dist, key=lambda x: x[0])  # the first of equal distances
        second = values[1] if len(values) > 1 else 10_000
        if first[0] > max_hamming or not (second >= 10_000 or first[0] < ratio * second):
            continue
        c = first[1]
        if c not in best or first[0] < best[c][0]:
            best[c] = (first[0], p)
    ki = np.array(sorted(best), int)
    return np.array([best[c][1] for c in ki], int), ki


def _plain_nearest(points, q, radius, k):
    """The k points nearest to q within radius, nearest first, equal distances by index."""
    d = np.sqrt(((points - q) ** 2).sum(1))
    within = np.flatnonzero(d <= radius)
    return within[np.lexsort((within, d[within]))][:k]


def test_the_grid_finds_the_k_nearest_within_the_radius_with_ties_by_index():
    """PointGrid.nearest against sorting every distance: integer positions (many equal distances, repeated
    points), queries outside the points' extent, radii across several cells, NaN and infinite queries."""
    rng = np.random.default_rng(5)
    pts = rng.integers(-20, 120, (300, 2)).astype(np.float64)
    pts[200:220] = pts[:20]  # the same position twice
    q = np.vstack([rng.uniform(-60, 160, (400, 2)), rng.integers(-20, 120, (100, 2)), [[np.nan, 5.0], [np.inf, 0.0]]])
    radius = rng.uniform(0.5, 50, len(q))
    for k in (1, 5, 8):
        got = PointGrid.of(pts, cell_px=7.0).nearest(q, radius, k)
        for i in range(len(q)):
            want = _plain_nearest(pts, q[i], radius[i], k) if np.isfinite(q[i]).all() else np.zeros(0, int)
            assert np.array_equal(got[i][got[i] >= 0], want) and (got[i][len(want):] == -1).all(), (k, i)
    assert (PointGrid.of(pts).nearest(q[:3], 1e9, 300) >= 0).all()  # everything, with one radius for all


@pytest.mark.parametrize("grid", [False, True])
def test_match_near_predictions_follows_its_rules(grid):
    """Ratio test against the second candidate (a tie at the least fails), radius, octave and `taken`
    filters, one prediction per keypoint (the closest, the first of equals): the compiled search against a
    plain one on random keypoints with descriptors drawn from a few shared bases (many near-ties)."""
    rng = np.random.default_rng(3)
    n, p = 400, 300
    base = rng.integers(0, 256, (12, 32), dtype=np.uint8)
    desc_kp = base[rng.integers(0, 12, n)] ^ (rng.random((n, 32)) < 0.05).astype(np.uint8)
    feats = Features(rng.uniform(0, 200, (n, 2)), rng.integers(0, 4, n), np.ones(n, np.float32), desc_kp,
                     np.ones(n, np.float32))
    pick = rng.integers(0, n, p)
    uv_pred = feats.uv[pick] + rng.normal(0, 4, (p, 2))
    desc = desc_kp[pick] ^ (rng.random((p, 32)) < 0.05).astype(np.uint8)
    radius = rng.uniform(3, 12, p)
    level, taken = rng.integers(0, 4, p), rng.random(n) < 0.1
    got = match_near_predictions(KeypointIndex(feats, grid), uv_pred, desc, radius, 60, 0.9, level, taken)
    want = _reference_near_predictions(feats, uv_pred, desc, radius, 60, 0.9, level, taken)
    assert len(got[0]) > 50 and np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def test_features_concat_select():
    f = Features(np.zeros((3, 2)), np.arange(3), np.ones(3, np.float32), np.zeros((3, 32), np.uint8),
                 np.ones(3, np.float32))
    g = Features.concat([f, f.select(np.array([True, False, True])), Features.empty()])
    assert len(g) == 5 and list(g.octave) == [0, 1, 2, 0, 2]
