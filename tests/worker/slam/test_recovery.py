"""Maps that start right and recover: the start threshold, young-map reset and new maps after a loss."""
from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from tests.worker.slam.synthetic_room import pose, render, trajectory, write_sequence
from worker.slam.camera import Camera
from worker.slam.config import PipelineConfig, TrackingConfig
from worker.slam.geometry.se3 import inv, pose_distance
from worker.slam.io.sequence import Sequence
from worker.slam.pipeline import run_pipeline
from worker.slam.presets import get_preset
from worker.slam.run.parts import build_slam
from worker.slam.tracking.recovery import LossAction, after_loss, can_start_map
from worker.slam.tracking.tracker import Tracker

CAM = Camera(525.0, 525.0, 319.5, 239.5, 5000.0, name="synthetic")
BEHIND = pose([0.1, 0.0, 0.2], 180)  # the opposite wall: nothing the first frames saw


def _tracking(cfg: PipelineConfig, **changes: Any) -> PipelineConfig:
    return replace(cfg, tracking=replace(cfg.tracking, **changes))


def test_loss_policy_waits_then_resets_young_maps_and_starts_new_ones():
    cfg = TrackingConfig(new_map_after_lost=2, reset_max_keyframes=5)
    assert after_loss(1, 20, cfg) is LossAction.WAIT
    assert after_loss(2, 5, cfg) is LossAction.RESET
    assert after_loss(3, 6, cfg) is LossAction.NEW_MAP
    assert not can_start_map(cfg.init_min_points - 1, cfg) and can_start_map(cfg.init_min_points, cfg)


def test_map_waits_for_a_frame_that_gives_enough_points():
    tr = build_slam(CAM, get_preset("orb-only")).tracker
    rgb, depth = render(pose([0, 0, 0], 0))
    sparse = depth.copy()
    sparse[:, 30:] = 0  # depth only in a thin strip: a handful of points
    res = tr.track(0, 0.0, rgb, sparse)
    assert not res.ok and len(tr.map) == 0
    res = tr.track(1, 1 / 30, rgb, depth)
    assert res.ok and res.keyframe is not None
    assert tr.map.points.n_alive >= tr.tc.init_min_points


def _lose_view(tr: Tracker):
    """Track the first frames, then show the opposite wall: tracking and relocalisation both fail."""
    poses = trajectory(6, yaw_span_deg=5)
    for i, T in enumerate(poses):
        assert tr.track(i, i / 30, *render(T)).ok
    old_points = tr.map.points.n
    pred = tr.predicted_pose()
    res = tr.track(6, 6 / 30, *render(BEHIND))
    return res, pred, old_points


def test_a_loss_starts_a_new_map_at_the_prediction_that_then_tracks():
    tr = build_slam(CAM, get_preset("orb-only")).tracker
    res, pred, old_points = _lose_view(tr)
    assert not res.ok and res.new_map and not res.relocalised and res.keyframe is not None
    assert np.allclose(res.T_WC, pred) and np.allclose(res.keyframe.T_WC, pred)
    # the young first map (< 6 keyframes) was discarded; the new one holds only the new keyframe's points
    p = tr.map.points
    assert not p.alive[:old_points].any() and p.alive[old_points: p.n].all()
    # the next frames track against the new map, with the true motion relative to its first keyframe
    moved = BEHIND @ pose([0.01, 0.0, 0.005], 0.5)
    nxt = tr.track(7, 7 / 30, *render(moved))
    assert nxt.ok and not nxt.new_map and nxt.n_tracked >= tr.tc.min_matches
    dt, dr = pose_distance(inv(res.T_WC) @ nxt.T_WC, inv(BEHIND) @ moved)
    assert dt < 0.01 and np.degrees(dr) < 0.5


def test_an_established_map_is_kept_when_a_new_one_starts():
    tr = build_slam(CAM, _tracking(get_preset("orb-only"), reset_max_keyframes=0)).tracker
    res, _, old_points = _lose_view(tr)
    assert res.new_map
    assert tr.map.points.alive[:old_points].any()  # still there for relocalisation and loop closure


def test_waiting_keeps_the_frame_lost_without_a_new_map():
    tr = build_slam(CAM, _tracking(get_preset("orb-only"), new_map_after_lost=3)).tracker
    res, _, _ = _lose_view(tr)
    assert not res.ok and not res.new_map and res.keyframe is None


def test_metrics_count_new_maps(tmp_path):
    poses = np.concatenate([trajectory(6, yaw_span_deg=5), [BEHIND, BEHIND @ pose([0.01, 0.0, 0.005], 0.5)]])
    seq = Sequence(write_sequence(tmp_path / "seq", poses), CAM)
    cfg = get_preset("orb-only")
    cfg = replace(cfg, dense=replace(cfg.dense, enabled=False))
    run = run_pipeline(seq, cfg)
    assert (run.metrics["new_maps"], run.metrics["lost"], run.metrics["map_merges"]) == (1, 1, 0)
    assert run.tracked.tolist() == [True] * 6 + [False, True]


def test_a_new_map_that_sees_the_old_one_again_is_merged_onto_it():
    tr = build_slam(CAM, _tracking(get_preset("orb-only"), reset_max_keyframes=0)).tracker
    poses = trajectory(6, yaw_span_deg=5)
    res, _, _ = _lose_view(tr)
    assert res.new_map
    # turn from the opposite wall back to the first view, tracking in the new map until it merges
    merged = None
    for k, yaw in enumerate(np.arange(175.0, -1.0, -5.0)):
        T = pose([0.1, 0.0, 0.2], yaw)
        got = tr.track(7 + k, (7 + k) / 30, *render(T))
        assert got.ok
        if got.merged:
            merged = (got, T)
            break
    assert merged is not None and len(tr.map_starts) == 1
    got, T = merged
    dt, dr = pose_distance(got.T_WC, inv(poses[0]) @ T)  # the first map's world, bridge error removed
    # 2.27 cm on this project's dev VM from 604a4fa on (same pinned packages; under 2 cm where CI ran): the
    # failure this guards against is a merge 180 degrees or metres off
    assert dt < 0.03 and np.degrees(dr) < 1
    # and the new map's first keyframe moved with it (it was placed at the prediction, 180 degrees off)
    dt, _ = pose_distance(res.keyframe.T_WC, inv(poses[0]) @ BEHIND)
    assert dt < 0.05
