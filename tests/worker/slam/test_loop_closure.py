"""Loop closure: pose-graph correction of a drifted loop, and detection + correction on a rendered 360° turn."""
from __future__ import annotations

import numpy as np
import pytest

from tests.worker.slam.synthetic_room import pose, render
from worker.slam.camera import Camera
from worker.slam.evaluation.metrics import evaluate
from worker.slam.geometry.se3 import exp_se3, inv
from worker.slam.io.trajectory import Trajectory
from worker.slam.mapping.loop_closure import LoopCloser
from worker.slam.mapping.pose_graph import optimize_pose_graph
from worker.slam.presets import get_preset
from worker.slam.run.parts import build_slam

CAM = Camera(525.0, 525.0, 319.5, 239.5, 5000.0, name="synthetic")


def _circle(n: int) -> np.ndarray:
    return np.stack([pose([np.sin(a), 0.0, 1 - np.cos(a)], np.degrees(a)) for a in np.linspace(0, 2 * np.pi, n,
                                                                                              endpoint=False)])


def test_pose_graph_closes_a_drifted_loop():
    gt = _circle(40)
    rng = np.random.default_rng(0)
    # odometry with a systematic bias -> the chained poses drift
    odo = [inv(gt[i]) @ gt[i + 1] @ exp_se3(np.r_[0.006, 0, 0.003, 0, 0.004, 0] + rng.normal(0, 1e-4, 6))
           for i in range(len(gt) - 1)]
    drifted = [gt[0]]
    for Z in odo:
        drifted.append(drifted[-1] @ Z)
    drifted = np.stack(drifted)
    edges = [(i, i + 1, Z, 1.0) for i, Z in enumerate(odo)]
    edges.append((0, len(gt) - 1, inv(gt[0]) @ gt[-1], 10.0))  # the loop: measured exactly
    fixed = optimize_pose_graph(drifted, edges, fixed=0)
    err_before = np.linalg.norm(drifted[:, :3, 3] - gt[:, :3, 3], axis=1).max()
    err_after = np.linalg.norm(fixed[:, :3, 3] - gt[:, :3, 3], axis=1).max()
    assert err_before > 0.1
    assert err_after < 0.6 * err_before  # a biased chain cannot be made exact, only spread out
    assert np.linalg.norm(fixed[-1, :3, 3] - gt[-1, :3, 3]) < 0.005  # the loop end snaps to the measurement
    assert np.allclose(fixed[0], drifted[0])  # the gauge node did not move


def test_pose_graph_edge_without_translation_weight_constrains_rotation_only():
    odometry = exp_se3(np.r_[0.5, 0.0, 0.0, 0.0, 0.0, 0.0])  # says: 0.5 m along x, not rotated
    strong = exp_se3(np.r_[0.0, 0.3, 0.0, 0.0, 0.0, 0.1])  # says: 0.3 m along y, 0.1 rad about z, weighted 100x
    edges = [(0, 1, odometry, 1.0), (0, 1, strong, 100.0)]
    start = np.stack([np.eye(4), odometry])
    rot_only = optimize_pose_graph(start, edges, trans_weights=np.array([1.0, 0.0]))
    both = optimize_pose_graph(start, edges)
    for out in (rot_only, both):  # the rotation follows the strong edge either way
        assert np.allclose(out[1][:3, :3], strong[:3, :3], atol=2e-3)
    assert np.allclose(rot_only[1][:3, 3], odometry[:3, 3], atol=1e-3)  # its translation is not weighed
    assert np.allclose(both[1][:3, 3], strong[:3, 3], atol=0.02)


@pytest.fixture(scope="module")
def turn_run():
    """A full 360° turn in the room, back to the start: the end must close a loop with the first keyframes."""
    n = 80
    poses = np.stack([pose([0.2 * np.sin(a), 0.0, 0.2 * (1 - np.cos(a))], np.degrees(a), -10)
                      for a in np.linspace(0, 2 * np.pi, n + 1)[:-1]])
    poses = np.concatenate([poses, poses[:8]])  # continue over the start
    cfg = get_preset("orb-only", {"loop": {"min_keyframe_gap": 6, "min_correction_m": 0.0},
                                  # exact synthetic depth deserves the full (ORB-SLAM2) depth weight
                                  "tracking": {"keyframe_max_frames": 5, "virtual_baseline_m": 0.08}})
    parts = build_slam(CAM, cfg)
    tr, mapper = parts.tracker, parts.mapper
    closer = LoopCloser(parts.map, cfg.loop, parts.sensor)
    est = []
    for i, T in enumerate(poses):
        rgb, depth = render(T)
        res = tr.track(i, i / 30, rgb, depth)
        assert res.ok
        if res.keyframe is not None:
            mapper.process(res.keyframe)
            closer.process(res.keyframe)
            tr.on_map_updated(res)
        est.append(res.T_WC)
    return poses, tr, closer


def test_loop_detected_and_applied_on_a_rendered_turn(turn_run):
    poses, tr, closer = turn_run
    assert closer.n_loops >= 1 and closer.n_applied >= 1
    # the corrected keyframes agree with the truth (after SE(3) alignment, as ATE)
    kfs = tr.map.keyframes
    ev = evaluate(Trajectory(np.array([k.frame_index for k in kfs], float), poses[[k.frame_index for k in kfs]]),
                  Trajectory(np.array([k.frame_index for k in kfs], float), tr.map.poses()), rpe_delta_s=5)
    # (the drift of this turn is a bend that comes back, not a random walk: the graph spreads the loop's
    # 1.3 cm / 0.8 degree correction around the turn and the ATE stays at the level before the correction)
    assert ev.ate.rmse < 0.02
    # across the closed loop the keyframes agree with the truth
    cand, cur, _, _ = closer.loop_edges[0]
    # a true revisit: the truth puts the two keyframes' cameras within a few centimetres
    assert np.linalg.norm(poses[kfs[cand].frame_index][:3, 3] - poses[kfs[cur].frame_index][:3, 3]) < 0.05
    rel = inv(kfs[cand].T_WC) @ kfs[cur].T_WC
    rel_gt = inv(poses[kfs[cand].frame_index]) @ poses[kfs[cur].frame_index]
    assert np.linalg.norm(rel[:3, 3] - rel_gt[:3, 3]) < 0.01


def test_a_sequence_without_revisits_closes_no_loop():
    """A sweep along the room that never comes back: whatever the vocabulary proposes, no loop is closed."""
    n = 70
    poses = np.stack([pose([-0.6 + 1.2 * i / n, 0.0, 0.3 * np.sin(i / n * np.pi)], 200.0 * i / n - 100.0, -10)
                      for i in range(n)])
    cfg = get_preset("orb-only", {"loop": {"min_keyframe_gap": 6, "min_correction_m": 0.0, "consistency": 1},
                                  "tracking": {"keyframe_max_frames": 5, "virtual_baseline_m": 0.08}})
    parts = build_slam(CAM, cfg)
    closer = LoopCloser(parts.map, cfg.loop, parts.sensor)
    for i, T in enumerate(poses):
        rgb, depth = render(T)
        res = parts.tracker.track(i, i / 30, rgb, depth)
        assert res.ok
        if res.keyframe is not None:
            parts.mapper.process(res.keyframe)
            closer.process(res.keyframe)
            parts.tracker.on_map_updated(res)
    assert len(parts.map) >= 12  # enough keyframes past the gap for detection to run
    assert closer.n_loops == 0 and closer.n_applied == 0 and not closer.loop_edges
