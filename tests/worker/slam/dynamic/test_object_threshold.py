"""The per-object threshold (`threshold.mode: object`): each segment's motion, its covariance and its Δd."""
import numpy as np
import pytest

from tests.worker.slam.dynamic.scene import K
from tests.worker.slam.dynamic.test_culling import run
from worker.slam.config import ConfigError
from worker.slam.config_values import apply_values as _apply
from worker.slam.dynamic.object_motion import ObjectMotionConfig, estimate_object_motion
from worker.slam.dynamic.threshold import ThresholdConfig, adaptive_threshold, motion_entropy, object_threshold

OBJECT = ThresholdConfig(mode="object")


def _points(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-0.3, 0.3, n), rng.uniform(-0.4, 0.4, n), rng.uniform(1.1, 1.4, n)])


def _project(X: np.ndarray, T: np.ndarray) -> np.ndarray:
    P = X @ T[:3, :3].T + T[:3, 3]
    return (P[:, :2] / P[:, 2:]) * np.diag(K)[:2] + K[:2, 2]


def _moved(tx: float, yaw_deg: float) -> np.ndarray:
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
    T[:3, 3] = [tx, 0.01, 0.0]
    return T


def test_entropy_of_a_known_covariance():
    cov = np.array([[4.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 0.5]])  # det = 3.5
    assert motion_entropy(cov) == pytest.approx(0.5 * (3 * np.log(2 * np.pi * np.e) + np.log(3.5)))


def test_gauss_newton_recovers_an_object_motion_and_its_uncertainty_shrinks_with_points():
    T = _moved(0.04, 2.0)
    rng = np.random.default_rng(1)
    estimates = {}
    for n in (10, 200):
        X = _points(n)
        uv = _project(X, T) + rng.normal(0, 0.5, (n, 2))
        m = estimate_object_motion(X, uv, K, None)
        assert m is not None and m.cov.shape == (6, 6)
        assert np.abs(m.T[:3, 3] - T[:3, 3]).max() < 0.01
        assert 0.2 < m.rms_px < 0.8
        estimates[n] = m
    assert motion_entropy(estimates[200].cov) < motion_entropy(estimates[10].cov) - 5


def test_few_points_give_a_translation_or_nothing():
    X = _points(12)
    uv = _project(X, _moved(0.02, 0.0))
    cfg = ObjectMotionConfig()
    three = estimate_object_motion(X[:cfg.min_points_6dof - 1], uv[:cfg.min_points_6dof - 1], K, None, cfg)
    assert three is not None and three.cov.shape == (3, 3)
    assert np.abs(three.T[:3, 3] - [0.02, 0.01, 0.0]).max() < 1e-3
    assert estimate_object_motion(X[:cfg.min_points - 1], uv[:cfg.min_points - 1], K, None, cfg) is None


def test_object_threshold_grows_with_the_entropy_and_scales_its_midpoint_with_the_dofs():
    small, large = object_threshold(np.eye(6) * 1e-7, OBJECT)[0], object_threshold(np.eye(6) * 1e-3, OBJECT)[0]
    assert OBJECT.d_min <= small < large <= OBJECT.d_max
    h3 = OBJECT.object_h0 * 3 / 6
    cov3 = np.eye(3) * np.exp((2 * h3 - 3 * np.log(2 * np.pi * np.e)) / 3)  # a 3x3 Σ whose entropy is h3
    assert object_threshold(cov3, OBJECT)[0] == pytest.approx(adaptive_threshold(None, OBJECT))


@pytest.mark.parametrize("predicted", [False, True])
@pytest.mark.parametrize("board_dx, moving", [(0.0, False), (0.06, True)])
def test_object_mode_decides_a_moving_and_a_static_board(board_dx, moving, predicted):
    res, kp, _ = run(board_dx, predicted=predicted, threshold=OBJECT)
    semantic = [s for s in res.segments if s.kind == "semantic"]
    assert semantic and all(s.object_level for s in semantic)
    assert all(s.dynamic == moving for s in semantic)
    # the object's own Δd, not the frame's
    assert all(s.threshold_px != pytest.approx(res.threshold_px) for s in semantic)


def test_frame_mode_and_a_segment_with_too_few_points_use_the_frame_threshold():
    res, _, _ = run(0.06)
    assert all(not s.object_level and s.threshold_px == res.threshold_px for s in res.segments)
    few = run(0.06, threshold=OBJECT, object_motion=ObjectMotionConfig(min_points=100_000, min_points_6dof=100_000))[0]
    assert all(not s.object_level and s.threshold_px == few.threshold_px for s in few.segments)


def test_an_unknown_threshold_mode_is_refused():
    with pytest.raises(ConfigError):
        _apply(ThresholdConfig(), {"mode": "segment"}, "culling.threshold")
