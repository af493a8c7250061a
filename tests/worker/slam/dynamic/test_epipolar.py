"""Two-view geometry of culling: predicted positions, the fundamental matrix (seeded, RANSAC, USAC), PnP."""
import cv2
import numpy as np
import pytest

from tests.worker.slam.dynamic.scene import K, pose


def test_predicted_positions_follow_depth_and_rotation():
    from worker.slam.dynamic.epipolar import predict_positions
    uv = np.array([[100.0, 80.0], [320.0, 240.0], [500.0, 400.0]])
    z = np.array([1.0, 2.0, 0.0])  # the last one has no depth: a direction
    assert np.allclose(predict_positions(uv, z, np.eye(4), K), uv)
    T = pose(0.1, 0.0, 2.0)  # X_cur = T X_prev
    X = np.column_stack([(uv[:2, 0] - K[0, 2]) / K[0, 0] * z[:2], (uv[:2, 1] - K[1, 2]) / K[1, 1] * z[:2], z[:2]])
    Xc = X @ T[:3, :3].T + T[:3, 3]
    expected = np.column_stack([K[0, 0] * Xc[:, 0] / Xc[:, 2] + K[0, 2], K[1, 1] * Xc[:, 1] / Xc[:, 2] + K[1, 2]])
    H = K @ T[:3, :3] @ np.linalg.inv(K)  # points at infinity move by the rotation's homography
    h = H @ np.array([uv[2, 0], uv[2, 1], 1.0])
    got = predict_positions(uv, z, T, K)
    assert np.allclose(got[:2], expected) and np.allclose(got[2], h[:2] / h[2])


def _two_views(rng, n=150, outliers=0.3):
    """Matches (n, 2) px of random points 1.5-4 m away seen before and after a known motion (R, t), a share
    of them moved by 5-20 px (movers), with 0.2 px noise."""
    from scipy.spatial.transform import Rotation
    X = np.column_stack([rng.uniform(-1.5, 1.5, (n, 2)), rng.uniform(1.5, 4.0, n)])
    R, t = Rotation.from_euler("xyz", [1.0, -2.0, 0.5], degrees=True).as_matrix(), np.array([0.08, 0.01, 0.02])
    proj = lambda P: (P @ K.T)[:, :2] / P[:, 2:]  # noqa: E731
    p0, p1 = proj(X) + rng.normal(0, 0.2, (n, 2)), proj(X @ R.T + t) + rng.normal(0, 0.2, (n, 2))
    moved = rng.random(n) < outliers
    p1[moved] += rng.uniform(5, 20, (moved.sum(), 2)) * rng.choice([-1, 1], (moved.sum(), 2))
    return p0, p1, R, t, moved


def test_a_fundamental_matrix_seeded_by_a_nearby_pose_separates_movers_like_ransac():
    """The seed (a pose 0.3° and 1 cm off) replaces RANSAC's hypotheses: the least-squares fit on what it
    explains tells movers from static points at least as well as RANSAC, with residuals no larger; a seed
    that explains too little gives None (the caller then runs RANSAC)."""
    from scipy.spatial.transform import Rotation

    from worker.slam.dynamic.epipolar import (
        epipolar_distance,
        fundamental_from_seed,
        fundamental_of_pose,
        fundamental_ransac,
    )
    rng = np.random.default_rng(2)
    p0, p1, R, t, moved = _two_views(rng)
    exact = epipolar_distance(fundamental_of_pose(R, t, K), p0, p1)
    assert np.median(exact[~moved]) < 0.3 and np.median(exact[moved]) > 3  # the helper's own F is right
    off = Rotation.from_euler("y", 0.3, degrees=True).as_matrix()
    F = fundamental_from_seed(p0, p1, fundamental_of_pose(off @ R, t + [0.01, 0, 0], K), 1.0, 0.5)
    d = epipolar_distance(F, p0, p1)
    ransac = epipolar_distance(fundamental_ransac(p0, p1, 1.0), p0, p1)
    right, right_ransac = ((d < 1.0) == ~moved).mean(), ((ransac < 1.0) == ~moved).mean()  # 1.0 and 0.98 here
    assert right > 0.95 and right >= right_ransac and np.median(d[~moved]) <= np.median(ransac[~moved])
    wrong = Rotation.from_euler("y", 5.0, degrees=True).as_matrix()
    assert fundamental_from_seed(p0, p1, fundamental_of_pose(wrong @ R, t, K), 1.0, 0.5) is None
    assert fundamental_from_seed(p0, p1, fundamental_of_pose(R, np.zeros(3), K), 1.0, 0.5) is None  # rotation only


@pytest.mark.parametrize("outliers", [0.3, 0.6])
def test_usac_separates_movers_and_finds_the_pose_like_ransac(outliers):
    """`usac` (F and the depth test's PnP fallback by OpenCV's USAC): with 30 % and 60 % movers it tells them
    from static points at least as well as classic RANSAC less 2 %, and its PnP finds the motion and the movers."""
    from worker.slam.dynamic.epipolar import epipolar_distance, fundamental_ransac
    from worker.slam.geometry.pnp import sqpnp_ransac
    rng = np.random.default_rng(5)
    p0, p1, R, t, moved = _two_views(rng, n=200, outliers=outliers)
    right = {}
    for usac in (False, True):
        d = epipolar_distance(fundamental_ransac(p0, p1, 1.0, usac=usac), p0, p1)
        right[usac] = ((d < 1.0) == ~moved).mean()
    assert right[True] > 0.95 and right[True] >= right[False] - 0.02
    # the depth test's PnP: first-view points X (N, 3) m seen after the motion, movers 21 px off
    z = rng.uniform(1.5, 4.0, len(p0))
    X = np.column_stack([(p0 - K[:2, 2]) / np.diag(K)[:2] * z[:, None], z])
    P = X @ R.T + t
    uv = (P @ K.T)[:, :2] / P[:, 2:] + rng.normal(0, 0.2, (len(P), 2)) + np.where(moved[:, None], 15.0, 0.0)
    rvec, tvec, inl = sqpnp_ransac(X, uv, K, 2.0, 300, 6, usac=True)
    angle = np.degrees(np.linalg.norm(cv2.Rodrigues(cv2.Rodrigues(rvec)[0] @ R.T)[0]))
    assert np.linalg.norm(tvec.ravel() - t) < 0.005 and angle < 0.1
    assert set(inl) == set(np.flatnonzero(~moved))


@pytest.mark.parametrize("outliers", [0.3, 0.6])
def test_ap3p_samples_find_the_pose_and_the_movers_like_sqpnp_samples(outliers):
    """`sqpnp_ransac(ap3p_samples=True)` (culling's default): AP3P hypotheses, SQPnP on their consensus, the
    same pose within 1 mm and 0.02 deg and the same inliers as SQPnP's own samples, movers 5-20 px off."""
    from worker.slam.geometry.pnp import sqpnp_ransac
    rng = np.random.default_rng(7)
    p0, _, R, t, moved = _two_views(rng, n=200, outliers=outliers)
    z = rng.uniform(1.5, 4.0, len(p0))
    X = np.column_stack([(p0 - K[:2, 2]) / np.diag(K)[:2] * z[:, None], z])
    P = X @ R.T + t
    uv = (P @ K.T)[:, :2] / P[:, 2:] + rng.normal(0, 0.2, (len(P), 2))
    uv[moved] += rng.uniform(5, 20, (moved.sum(), 2)) * rng.choice([-1, 1], (moved.sum(), 2))
    got = {ap3p: sqpnp_ransac(X, uv, K, 2.0, 300, 6, ap3p_samples=ap3p) for ap3p in (False, True)}
    for rvec, tvec, inl in got.values():
        angle = np.degrees(np.linalg.norm(cv2.Rodrigues(cv2.Rodrigues(rvec)[0] @ R.T)[0]))
        assert np.linalg.norm(tvec.ravel() - t) < 0.001 and angle < 0.02
        assert set(inl) == set(np.flatnonzero(~moved))
