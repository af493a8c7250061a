"""Frames re-solved against the final map: a pose tracked against points that BA later moved follows them."""
from __future__ import annotations

import numpy as np

from worker.slam.config import TrackingConfig
from worker.slam.geometry.se3 import exp_se3, inv, pose_distance, transform
from worker.slam.map.map_points import MapPoints
from worker.slam.mapping.frame_refit import FrameMatchLog, refit_poses
from worker.slam.sensor import SensorModel

K = np.array([[525.0, 0, 320], [0, 525.0, 240], [0, 0, 1]])
BF = 525.0 * 0.08
INV_SIGMA2 = 1.0 / 1.2 ** (2 * np.arange(8))
SENSOR = SensorModel(K, BF, (640, 480), 1.2 ** np.arange(8), INV_SIGMA2, None)
TC = TrackingConfig(min_matches=30)  # the tracker's Huber 2.45 px, 4 rounds of 8 iterations


def _scene(n: int = 300, seed: int = 0) -> tuple[MapPoints, np.ndarray, np.ndarray]:
    """Map points spread 1-4 m in front of the world origin and the true pose T_WC of a camera 10 cm aside."""
    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.uniform(-1.5, 1.5, n), rng.uniform(-1, 1, n), rng.uniform(1, 4, n)])
    pts = MapPoints()
    ids = pts.add(X, np.zeros((n, 32), np.uint8), np.zeros(3), np.zeros(n, int), 1.2, 0)
    T_WC = exp_se3(np.array([0.1, 0.02, -0.05, 0.01, -0.02, 0.005]))
    return pts, ids, T_WC


def _observe(pts: MapPoints, ids: np.ndarray, T_WC: np.ndarray, log: FrameMatchLog, noise_px: float = 0.0,
             seed: int = 1) -> None:
    Pc = transform(inv(T_WC), pts.pos[ids])
    uv = (Pc[:, :2] / Pc[:, 2:]) * [K[0, 0], K[1, 1]] + K[:2, 2]
    uv += np.random.default_rng(seed).normal(0, noise_px, uv.shape)
    octave = np.zeros(len(ids), int)
    log.add(np.asarray(ids, np.int64), uv, Pc[:, 2], octave, keep=True)


def test_a_frame_follows_the_points_that_bundle_adjustment_moved():
    pts, ids, T_true = _scene()
    log = FrameMatchLog()
    _observe(pts, ids, T_true, log, noise_px=0.3)
    # tracked against points that were off by a shared 2 cm shift: its stored pose carries that shift
    stored = T_true.copy()
    stored[:3, 3] += [0.02, -0.01, 0.015]
    poses = stored[None].copy()
    n, info = refit_poses(poses, log, pts, SENSOR, TC)
    assert n == 1 and info[0].shape == (6, 6) and np.all(np.linalg.eigvalsh(info[0]) > 0)
    dt_before, _ = pose_distance(stored, T_true)
    dt_after, dr_after = pose_distance(poses[0], T_true)
    assert dt_before > 0.02 and dt_after < 0.002 and dr_after < 0.002  # radians


def test_frames_without_enough_surviving_points_and_unlogged_frames_keep_their_poses():
    pts, ids, T_true = _scene()
    log = FrameMatchLog()
    _observe(pts, ids[:40], T_true, log)          # frame 0: 40 matches, 20 of whose points are culled later
    log.add(np.full(5, -1), np.zeros((5, 2)), np.zeros(5), np.zeros(5, int), keep=False)  # frame 1: lost
    _observe(pts, ids, T_true, log)               # frame 2: all points
    pts.kill(ids[:20])
    shifted = T_true.copy()
    shifted[:3, 3] += 0.01
    poses = np.stack([shifted, shifted, shifted])
    n, info = refit_poses(poses, log, pts, SENSOR, TC)
    assert n == 1 and info[0] is None and info[1] is None and info[2] is not None
    assert np.array_equal(poses[0], shifted) and np.array_equal(poses[1], shifted)
    assert pose_distance(poses[2], T_true)[0] < 1e-4
    assert log.frames[1] is None and len(log.frames[0].ids) == 40 and log.frames[0].uv.dtype == np.float32


def test_outlier_matches_do_not_drag_the_refit():
    pts, ids, T_true = _scene(seed=3)
    log = FrameMatchLog()
    _observe(pts, ids, T_true, log, noise_px=0.3)
    log.frames[0].uv[:30] += 40.0  # a tenth of the matches wrong (a person's points that slipped through)
    poses = T_true[None].copy()
    poses[0][:3, 3] += 0.01
    refit_poses(poses, log, pts, SENSOR, TC)
    assert pose_distance(poses[0], T_true)[0] < 0.002


def test_a_keyframe_keeps_its_pose_but_gets_the_information_of_its_solve():
    pts, ids, T_true = _scene(seed=4)
    log = FrameMatchLog()
    Pc = transform(inv(T_true), pts.pos[ids])
    uv = (Pc[:, :2] / Pc[:, 2:]) * [K[0, 0], K[1, 1]] + K[:2, 2]
    log.add(np.asarray(ids, np.int64), uv, Pc[:, 2], np.zeros(len(ids), int), keep=True, keyframe=True)
    shifted = T_true.copy()
    shifted[:3, 3] += 0.01
    poses = shifted[None].copy()
    n, info = refit_poses(poses, log, pts, SENSOR, TC)
    assert n == 0 and np.array_equal(poses[0], shifted) and info[0] is not None
