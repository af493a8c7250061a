"""Motion model, PnP + motion-only BA against known poses, covariance, keyframe policy, tracker on a room."""
from __future__ import annotations

import numpy as np
import pytest

from tests.worker.slam.synthetic_room import K_SYN, pose, render, trajectory
from worker.slam.camera import Camera
from worker.slam.config import TrackingConfig
from worker.slam.features.types import Features
from worker.slam.geometry.pnp import pnp_ransac
from worker.slam.geometry.pose_optimizer import optimize_pose, pose_entropy
from worker.slam.geometry.se3 import exp_se3, inv, log_se3, pose_distance, transform
from worker.slam.presets import get_preset
from worker.slam.run.parts import build_slam
from worker.slam.tracking.inputs import TrackInputs
from worker.slam.tracking.keyframe_policy import KeyframeDecisionInput, need_keyframe
from worker.slam.tracking.motion import ConstantVelocityModel

CAM = Camera(525.0, 525.0, 319.5, 239.5, 5000.0, name="synthetic")


def _scene(rng, n=300):
    T_WC = pose([0.2, -0.1, 0.3], 20, -10)
    Xc = np.column_stack([rng.uniform(-1.5, 1.5, n), rng.uniform(-1, 1, n), rng.uniform(1.0, 4.0, n)])
    uv = Xc[:, :2] / Xc[:, 2:] * K_SYN[0, 0] + K_SYN[:2, 2]
    return T_WC, transform(T_WC, Xc), uv, Xc[:, 2]


def test_se3_exp_log_roundtrip():
    xi = np.array([0.1, -0.2, 0.3, 0.2, -0.1, 0.4])
    assert np.allclose(log_se3(exp_se3(xi)), xi)
    T = exp_se3(xi)
    assert np.allclose(inv(T) @ T, np.eye(4))


def test_constant_velocity_model_predicts_constant_motion():
    m = ConstantVelocityModel()
    assert m.predict() is None
    step = exp_se3(np.array([0.01, 0, 0.02, 0, 0.01, 0]))
    T = pose([0, 0, 0], 5)
    m.update(T)
    assert np.allclose(m.predict(), T)  # no velocity yet: stay
    m.update(T @ step)
    assert np.allclose(m.predict(), T @ step @ step)
    m.reset(T)
    assert np.allclose(m.predict(), T)


def test_pnp_and_motion_only_ba_recover_known_pose_with_outliers():
    rng = np.random.default_rng(1)
    T_WC, X, uv, z = _scene(rng)
    uv_noisy = uv + rng.normal(0, 0.5, uv.shape)
    outl = rng.random(len(uv)) < 0.2
    uv_noisy[outl] += rng.uniform(-60, 60, (outl.sum(), 2))
    T0, inl0 = pnp_ransac(X, uv_noisy, K_SYN)
    assert pose_distance(T0, T_WC)[0] < 0.05
    est = optimize_pose(T0, X, uv_noisy, z, np.ones(len(X)), K_SYN, bf=525 * 0.08)
    dt, dr = pose_distance(est.T_WC, T_WC)
    assert dt < 0.005 and np.degrees(dr) < 0.2
    assert not est.inliers[outl].any() or est.inliers[outl].mean() < 0.05
    assert est.inliers[~outl].mean() > 0.9
    # covariance from the normal equations: symmetric positive definite, shrinks with more points
    C = est.covariance
    assert C.shape == (6, 6) and np.allclose(C, C.T) and np.all(np.linalg.eigvalsh(C) > 0)
    half = optimize_pose(T0, X[::2], uv_noisy[::2], z[::2], np.ones(len(X[::2])), K_SYN, bf=525 * 0.08)
    assert pose_entropy(half.covariance) > pose_entropy(C)


@pytest.mark.parametrize("robust", [True, False])
@pytest.mark.parametrize("ur_u", [1.0, 0.0])
def test_compiled_step_terms_are_the_numpy_expressions_bit_for_bit(robust, ur_u):
    """Motion-only BA's compiled per-observation terms against the numpy expressions they replace (residual at
    (1, 1, 1) behind the camera, Huber weights, prior weights, observations without depth): equal bits, so the
    trajectories stay byte-identical."""
    from worker.slam.geometry import reprojection as rp
    rng = np.random.default_rng(5)
    n, bf = 300, 40.0
    Pc = np.column_stack([rng.normal(0, 1, n), rng.normal(0, 1, n), rng.uniform(0.3, 5, n)])
    Pc[:7, 2] = rng.uniform(-1, 1e-3, 7)  # behind or on the camera plane
    z = np.where(rng.random(n) < 0.8, Pc[:, 2] + rng.normal(0, 0.02, n), 0.0)
    uv = rp.project(np.where(Pc[:, 2:3] > 1e-3, Pc, 1.0), K_SYN, bf)[:, :2] + rng.normal(0, 2, (n, 2))
    obs, has = rp.observations(uv, z, bf, ur_u)
    roww = rp.residual_weights(has, None if ur_u == 1.0 else rng.uniform(0.1, 12.0, n))
    info = 1.2 ** -rng.integers(0, 8, n).astype(float) * 2
    good = (rng.random(n) < 0.9) & (Pc[:, 2] > 1e-3)
    prior = rng.uniform(0.2, 1.0, n)
    e = (obs - rp.project(np.where(Pc[:, 2:3] > 1e-3, Pc, 1.0), K_SYN, bf, ur_u)) * roww
    chi2 = info * (e**2).sum(1)
    w = np.where(good, info * (rp.huber_weights(chi2, 2.45) if robust else 1.0) * prior, 0.0)
    J = rp.jacobian_pose(Pc, rp.jacobian_point(Pc, K_SYN, bf, ur_u)) * roww[:, :, None]
    got = rp.pose_step_terms(Pc, obs, roww, info, good, prior, K_SYN[0, 0], K_SYN[1, 1], K_SYN[0, 2],
                             K_SYN[1, 2], bf, 2.45, robust, ur_u)
    for a, b in zip(got, (e, J, J * w[:, None, None])):
        assert a.shape == b.shape and np.array_equal(a, b)


def test_prior_weights_let_a_minority_of_established_points_win():
    """Three fifths of the matches sit on things that moved 6 cm together since they were mapped (people walking
    side by side): the plain solve follows them; weighting them 0.1 (new points) against 1 (points matched in
    many frames) recovers the static pose."""
    rng = np.random.default_rng(3)
    T_WC, X, uv, z = _scene(rng, 250)
    moved = np.arange(len(X)) < 150
    X_map = X.copy()
    X_map[moved] += np.array([0.06, 0.0, 0.0])  # where the map put them: they have moved since
    plain = optimize_pose(T_WC, X_map, uv, z, np.ones(len(X)), K_SYN, bf=525 * 0.08)
    weighted = optimize_pose(T_WC, X_map, uv, z, np.ones(len(X)), K_SYN, bf=525 * 0.08,
                             weights=np.where(moved, 0.1, 1.0))
    assert pose_distance(plain.T_WC, T_WC)[0] > 0.04  # dragged by the majority
    assert pose_distance(weighted.T_WC, T_WC)[0] < 0.005
    assert weighted.inliers[~moved].mean() > 0.9 and weighted.inliers[moved].mean() < 0.1


def test_keyframe_policy():
    cfg = TrackingConfig()
    base = dict(frames_since_kf=5, tracked=400, ref_tracked=400, close_tracked=300, close_untracked=10)
    assert not need_keyframe(KeyframeDecisionInput(**base), cfg)
    assert need_keyframe(KeyframeDecisionInput(**{**base, "tracked": 250}), cfg)  # weak tracking
    assert need_keyframe(KeyframeDecisionInput(**{**base, "frames_since_kf": cfg.keyframe_max_frames}), cfg)
    assert need_keyframe(KeyframeDecisionInput(**{**base, "close_tracked": 50, "close_untracked": 200}), cfg)
    assert not need_keyframe(KeyframeDecisionInput(**{**base, "tracked": 10}), cfg)  # too weak to anchor


@pytest.fixture(scope="module")
def room_run():
    poses = trajectory(45, yaw_span_deg=40)
    tr = build_slam(CAM, get_preset("orb-only")).tracker
    results = []
    for i, T in enumerate(poses):
        rgb, depth = render(T)
        results.append(tr.track(i, i / 30, rgb, depth))
    return poses, tr, results


def test_tracker_synthetic_room_subcentimetre(room_run):
    poses, tr, results = room_run
    assert all(r.ok for r in results)
    est = np.stack([r.T_WC for r in results])
    gt = inv(poses[0]) @ poses  # the tracker's world is the first camera
    err = np.linalg.norm(est[:, :3, 3] - gt[:, :3, 3], axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.01
    assert results[0].keyframe is not None and len(tr.map) >= 2  # keyframes inserted along the way
    assert all(r.covariance is not None for r in results[1:])


def test_tracker_hooks_exclude_mask_and_extra_features():
    poses = trajectory(6, yaw_span_deg=5)
    tr = build_slam(CAM, get_preset("orb-only")).tracker
    exclude = np.zeros((480, 640), bool)
    exclude[100:300, 200:400] = True
    extra = Features(np.array([[250.0, 150.0], [300.0, 200.0]]), np.zeros(2, int), np.ones(2, np.float32),
                     np.zeros((2, 32), np.uint8), np.zeros(2, np.float32))
    for i, T in enumerate(poses):
        rgb, depth = render(T)
        restored = depth.copy()
        res = tr.track(i, i / 30, rgb, depth,
                       TrackInputs(exclude_mask=exclude, extra_features=extra, restored_depth=restored))
        own = res.feats.uv[:-2]
        inside = (own[:, 0] >= 200) & (own[:, 0] < 400) & (own[:, 1] >= 100) & (own[:, 1] < 300)
        assert not inside.any()
        assert np.allclose(res.feats.uv[-2:], extra.uv) and (res.feats.depth[-2:] > 0).all()
        assert res.ok


def test_relocalisation_after_a_jump():
    poses = trajectory(12, yaw_span_deg=10)
    tr = build_slam(CAM, get_preset("orb-only")).tracker
    for i, T in enumerate(poses[:8]):
        rgb, depth = render(T)
        assert tr.track(i, i / 30, rgb, depth).ok
    # a wild motion-model prediction (as after a dropped stretch of frames) forces relocalisation
    tr.motion.reset(pose([1.5, 0.5, -1.0], 120))
    rgb, depth = render(poses[9])
    res = tr.track(9, 9 / 30, rgb, depth)
    assert res.ok and res.relocalised
    assert pose_distance(res.T_WC, inv(poses[0]) @ poses[9])[0] < 0.02


@pytest.mark.parametrize("retry", [True, False])
def test_an_overshooting_velocity_is_retried_from_the_last_pose_before_relocalisation(retry):
    """A velocity 25 cm and 15 deg off (as from a few badly tracked frames) puts the prediction where no map
    point matches: the frame is tracked from the last pose instead (`retry_from_last_pose`), not relocalised."""
    poses = trajectory(12, yaw_span_deg=10)
    tr = build_slam(CAM, get_preset("orb-only", {"tracking": {"retry_from_last_pose": retry}})).tracker
    for i, T in enumerate(poses[:8]):
        rgb, depth = render(T)
        assert tr.track(i, i / 30, rgb, depth).ok
    tr.motion.velocity = pose([0.25, 0.0, 0.05], 15)
    rgb, depth = render(poses[8])
    retries = tr.last_pose_retries
    res = tr.track(8, 8 / 30, rgb, depth)
    assert res.ok and pose_distance(res.T_WC, inv(poses[0]) @ poses[8])[0] < 0.01
    assert (tr.last_pose_retries - retries, res.relocalised) == ((1, False) if retry else (0, True))


def test_tracker_undistorts_keypoints_of_a_distorted_camera():
    import cv2

    dist = np.array([0.2, -0.5, 0.001, -0.001, 0.3])
    cam = Camera(525.0, 525.0, 319.5, 239.5, 5000.0, dist=tuple(dist), name="distorted")
    v, u = np.mgrid[0:480, 0:640].astype(np.float64)
    und = cv2.undistortPoints(np.stack([u, v], -1).reshape(-1, 1, 2), K_SYN, dist, P=K_SYN).reshape(480, 640, 2)
    mx, my = und[..., 0].astype(np.float32), und[..., 1].astype(np.float32)
    poses = trajectory(20, yaw_span_deg=15)
    tr = build_slam(cam, get_preset("orb-only")).tracker
    est = []
    for i, T in enumerate(poses):
        rgb, depth = render(T)
        rgb_d = cv2.remap(rgb, mx, my, cv2.INTER_LINEAR)  # what a distorted lens sees
        depth_d = cv2.remap(depth, mx, my, cv2.INTER_NEAREST)
        res = tr.track(i, i / 30, rgb_d, depth_d)
        assert res.ok
        est.append(res.T_WC)
    assert res.feats.uv_raw is not None and not np.allclose(res.feats.uv, res.feats.uv_raw)
    gt = inv(poses[0]) @ poses
    err = np.linalg.norm(np.stack(est)[:, :3, 3] - gt[:, :3, 3], axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.01


@pytest.mark.realdata
def test_relocalisation_on_real_frames(redkitchen):
    from worker.slam.camera import PRESETS
    from worker.slam.io.sequence import Sequence

    seq = Sequence(redkitchen, PRESETS["7scenes"])
    gt = seq.groundtruth.poses
    tr = build_slam(seq.camera, get_preset("orb-only")).tracker
    for i in range(0, 60, 2):
        f = seq[i]
        res = tr.track(i, f.timestamp, f.rgb, f.depth)
        assert res.ok
    # a wrong prediction (90 degrees off, 0.5 m away) makes the projection search fail -> relocalise
    tr.motion.reset(res.T_WC @ np.array([[0, -1, 0, 0.5], [1, 0, 0, 0], [0, 0, 1, 0.3], [0, 0, 0, 1.0]]))
    f = seq[25]
    res = tr.track(25, f.timestamp, f.rgb, f.depth)
    assert res.ok and res.relocalised
    dt, dr = pose_distance(res.T_WC, inv(gt[0]) @ gt[25])
    assert dt < 0.03 and np.degrees(dr) < 2
