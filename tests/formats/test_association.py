import numpy as np

from worker.slam.io.lists import associate


def _tum_associate(a, b, max_diff):
    """TUM associate.py's algorithm, literally: all pairs, sorted by difference, greedy."""
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
    assert associate(a, b, 0.02) == _tum_associate(a, b, 0.02)


def test_each_index_used_once():
    pairs = associate(np.array([0.0, 0.001]), np.array([0.0005]), 0.02)
    assert len(pairs) == 1
