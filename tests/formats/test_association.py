import tracemalloc

import numpy as np

from formats.association import MAX_DIFF_S, associate


def _tum_associate(a, b, max_diff, offset=0.0):
    """TUM associate.py's algorithm, literally: all pairs, sorted by difference (then indices), greedy."""
    b = [y + offset for y in b]
    cand = sorted((abs(x - y), i, j) for i, x in enumerate(a) for j, y in enumerate(b) if abs(x - y) < max_diff)
    ua, ub, out = set(), set(), []
    for _, i, j in cand:
        if i not in ua and j not in ub:
            ua.add(i)
            ub.add(j)
            out.append((i, j))
    return sorted(out)


def test_matches_tum_associate_on_jittered_stamps():
    rng = np.random.default_rng(1)
    a = np.sort(rng.uniform(0, 10, 300))
    b = np.sort(np.concatenate([a[::2] + rng.normal(0, 0.01, 150), rng.uniform(0, 10, 40)]))
    assert associate(a, b, 0.02) == _tum_associate(list(a), list(b), 0.02)


def test_matches_tum_associate_with_duplicates_and_ties():
    """Coarse grids make many equal timestamps and equal differences: the tie-breaking must be TUM's."""
    rng = np.random.default_rng(0)
    for _ in range(400):
        n, m = rng.integers(0, 30, 2)
        base = float(rng.choice([0.0, 5.0, 1305031102.0]))
        grid = float(rng.choice([0.001, 0.005, 0.01]))
        a = [float(x) for x in np.round(base + rng.integers(0, 40, n) * grid, 6)]
        b = [float(x) for x in np.round(base + rng.integers(0, 40, m) * grid + rng.choice([0.0, 0.0005]), 6)]
        offset = float(rng.choice([0.0, 0.003]))
        assert associate(a, b, MAX_DIFF_S, offset) == _tum_associate(a, b, MAX_DIFF_S, offset), (a, b, offset)


def test_each_index_used_once():
    pairs = associate(np.array([0.0, 0.001]), np.array([0.0005]), 0.02)
    assert len(pairs) == 1


def test_nothing_within_max_diff():
    assert associate([0.0, 1.0], [0.5], 0.02) == []
    assert associate([], [0.5]) == []


def test_thousands_of_equal_timestamps_pair_without_listing_candidates():
    """3000 equal stamps against 3000 near ones: 9 million candidate pairs if listed (issue 24, 3a)."""
    a = [1305031102.0] * 3000
    b = [1305031102.001] * 1500 + [1305031102.0] * 1500
    tracemalloc.start()
    try:
        pairs = associate(a, b)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(pairs) == 3000
    assert pairs[:2] == [(0, 1500), (1, 1501)]  # the equal stamps pair first, smallest indices together
    assert peak < 50e6
