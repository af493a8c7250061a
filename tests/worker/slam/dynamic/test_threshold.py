"""The frame's threshold Δd = f(H) and the motion entropy H of a pose covariance."""
import numpy as np
import pytest

from worker.slam.dynamic.threshold import ThresholdConfig, adaptive_threshold, motion_entropy


def test_threshold_grows_slowly_and_is_bounded():
    cfg = ThresholdConfig()
    hs = np.linspace(-80, 20, 50)
    ds = [adaptive_threshold(h, cfg) for h in hs]
    assert np.all(np.diff(ds) >= 0)
    assert cfg.d_min <= min(ds) and max(ds) <= cfg.d_max
    assert adaptive_threshold(cfg.h0, cfg) == pytest.approx((cfg.d_min + cfg.d_max) / 2)
    assert adaptive_threshold(None, ThresholdConfig(fixed=1.5)) == 1.5


def test_entropy_of_gaussian():
    cov = np.diag([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    expected = 0.5 * np.log((2 * np.pi * np.e) ** 6 * np.prod(np.diag(cov)))
    assert motion_entropy(cov) == pytest.approx(expected)
    assert motion_entropy(np.zeros((6, 6))) is None and motion_entropy(None) is None
