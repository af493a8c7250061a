"""The per-segment statistics of culling equal numpy's, bit for bit (the decisions compare them with Δd)."""
from __future__ import annotations

import numpy as np
import pytest

from worker.slam.dynamic.sorted_stats import median_of_sorted, quantile_of_sorted


@pytest.mark.parametrize("q", [0.0, 0.1, 0.25, 0.5, 1 / 3, 0.75, 0.9, 1.0])
def test_quantile_and_median_equal_numpy(q):
    rng = np.random.default_rng(int(q * 1000))
    for n in list(range(1, 40)) + [101, 1000]:
        v = np.sort(rng.exponential(3.0, n) * rng.choice([1e-3, 1.0, 1e3]))
        if n > 3:
            v[1:3] = v[0]  # ties
        assert quantile_of_sorted(v, q) == np.quantile(v, q)
        assert median_of_sorted(v) == np.median(v)
