"""Triangulated map points between keyframes: made for keypoints without map points, and on the room's walls."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from tests.worker.slam.synthetic_room import HALF, render, trajectory
from worker.slam.camera import Camera
from worker.slam.geometry.se3 import transform
from worker.slam.mapping.local_mapping import LocalMapper
from worker.slam.presets import get_preset
from worker.slam.run.parts import build_slam
from worker.slam.tracking.tracker import Tracker

CAM = Camera(525.0, 525.0, 319.5, 239.5, 5000.0, name="synthetic")


def _map_room(neighbours: int) -> tuple[Tracker, LocalMapper, np.ndarray, np.ndarray]:
    """Track and map the room with depth points only up to 2.5 m: the far walls are left to triangulation."""
    cfg = get_preset("orb-only")
    cfg = replace(cfg, mapping=replace(cfg.mapping, triangulate_neighbours=neighbours, new_point_max_depth_m=2.5))
    parts = build_slam(CAM, cfg)
    tr, mapper = parts.tracker, parts.mapper
    poses = trajectory(40, yaw_span_deg=30)
    made: list[np.ndarray] = []
    for i, T in enumerate(poses):
        res = tr.track(i, i / 30, *render(T))
        assert res.ok
        if res.keyframe is not None:
            n0 = tr.map.points.n
            mapper.process(res.keyframe)
            made.append(np.arange(n0, tr.map.points.n))
    return tr, mapper, np.concatenate(made), poses[0]


def test_triangulated_points_lie_on_the_walls_beyond_the_depth_range():
    tr, mapper, made, T0 = _map_room(5)
    p = tr.map.points
    alive = made[p.alive[made]]
    assert mapper.triangulated == len(made) and len(alive) >= 30
    X = transform(T0, p.pos[alive])  # the room's frame
    wall = np.min(np.abs(np.abs(X) - HALF), axis=1)
    assert np.median(wall) < 0.03 and np.percentile(wall, 90) < 0.08
    assert np.median(np.linalg.norm(p.pos[alive], axis=1)) > 2.5  # far structure depth did not give
    # each triangulated point is observed by two keyframes
    observed = np.concatenate([kf.point_ids for kf in tr.map.keyframes])
    assert (np.bincount(observed[observed >= 0], minlength=p.n)[alive] >= 2).all()


def test_triangulation_off_makes_no_points():
    _, mapper, made, _ = _map_room(0)
    assert mapper.triangulated == 0 and len(made) == 0
