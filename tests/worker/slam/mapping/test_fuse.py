"""Map-point fusion between covisible keyframes: duplicates merge, point-less keypoints gain observations, and a
keypoint whose depth disagrees with the point is left alone."""
from __future__ import annotations

import numpy as np

from worker.slam.camera import Camera
from worker.slam.features.types import Features
from worker.slam.geometry.se3 import inv
from worker.slam.map.keyframe import KeyFrame
from worker.slam.map.map import Map
from worker.slam.mapping.fuse import FuseGeometry, fuse_neighbours

CAM = Camera(525.0, 525.0, 319.5, 239.5, 5000.0, name="synthetic")
SCALES = 1.2 ** np.arange(8)
GEOMETRY = FuseGeometry(CAM.K, (CAM.width, CAM.height), SCALES, 1.0 / SCALES**2, CAM.fx * 0.08)
N = 200


def _keyframe(kf_id: int, T_WC: np.ndarray, X_w: np.ndarray, desc: np.ndarray) -> KeyFrame:
    """A keyframe at `T_WC` seeing world points `X_w` (N,3) exactly, at octave 0, with their depth."""
    T = inv(T_WC)
    Pc = X_w @ T[:3, :3].T + T[:3, 3]
    uv = Pc[:, :2] / Pc[:, 2:] * [CAM.fx, CAM.fy] + [CAM.cx, CAM.cy]
    feats = Features(uv, np.zeros(len(X_w), int), np.ones(len(X_w), np.float32), desc.copy(),
                     Pc[:, 2].astype(np.float32))
    return KeyFrame(kf_id, kf_id, float(kf_id), T_WC, feats, np.full(len(X_w), -1, np.int64))


def _two_keyframes() -> tuple[Map, np.ndarray]:
    """Keyframe 0 made points 0..N-1. Keyframe 1, 10 cm to the right, sees the same surface points: it tracked
    the first 20, made its own duplicates for 20..149 (1 mm off), has no point for 150..199, and for 180..199
    its depth reads half the true distance (a neighbouring surface's). Returns (map, the duplicates' ids)."""
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-1, 1, N), rng.uniform(-0.8, 0.8, N), rng.uniform(2, 4, N)])
    desc = rng.integers(0, 256, (N, 32), dtype=np.uint8)
    m = Map()
    T1 = np.eye(4)
    T1[0, 3] = 0.1
    kf0, kf1 = _keyframe(0, np.eye(4), X, desc), _keyframe(1, T1, X, desc)
    kf1.feats.depth[180:] *= 0.5
    p = m.points
    kf0.point_ids[:] = p.add(X, desc, np.zeros(3), np.zeros(N, int), 1.2, 0)
    m.add_keyframe(kf0)
    kf1.point_ids[:20] = kf0.point_ids[:20]
    p.n_obs[kf0.point_ids[:20]] += 1
    dup = p.add(X[20:150] + 0.001, desc[20:150], T1[:3, 3], np.zeros(130, int), 1.2, 1)
    kf1.point_ids[20:150] = dup
    m.add_keyframe(kf1)
    return m, dup


def test_fusion_adds_observations_and_keeps_duplicates_unless_merging():
    m, dup = _two_keyframes()
    kf0, kf1 = m.keyframes
    n = fuse_neighbours(m, kf1, 10, GEOMETRY, 3.0)
    p = m.points
    assert (kf1.point_ids[20:150] == dup).all() and p.alive[dup].all() and p.alive[:N].all()
    assert (kf1.point_ids[150:180] == kf0.point_ids[150:180]).all() and (kf1.point_ids[180:] == -1).all()
    assert (p.n_obs[kf0.point_ids[150:180]] == 2).all() and n == 30
    assert m.covis[1][0] == 50


def test_merging_fusion_merges_duplicates_and_adds_observations():
    m, dup = _two_keyframes()
    kf0, kf1 = m.keyframes
    assert m.covis[1][0] == 20
    n = fuse_neighbours(m, kf1, 10, GEOMETRY, 3.0, merge=True)
    p = m.points
    # duplicates merged: both keyframes name one alive point per surface point, the other died
    assert (kf0.point_ids[20:150] == kf1.point_ids[20:150]).all()
    assert p.alive[kf0.point_ids[:180]].all()
    assert p.alive[:N].sum() + p.alive[dup].sum() == N
    # point-less keypoints of keyframe 1 now observe keyframe 0's points, except where the depth disagrees
    assert (kf1.point_ids[150:180] == kf0.point_ids[150:180]).all()
    assert (kf1.point_ids[180:] == -1).all()
    assert (p.n_obs[kf0.point_ids[:180]] == 2).all() and (p.n_obs[kf0.point_ids[180:]] == 1).all()
    assert n == 130 + 30
    assert m.covis[1][0] == 180 and m.covis[0][1] == 180


def test_fusion_leaves_unrelated_points_alone():
    """Keypoints whose descriptors differ from the points projected onto them: nothing is fused."""
    m, dup = _two_keyframes()
    kf1 = m.keyframes[1]
    for kf in m.keyframes:
        kf.feats.desc[20:] = 255 - kf.feats.desc[20:]  # beyond the tracked 20, keypoints look different
    before = kf1.point_ids.copy()
    assert fuse_neighbours(m, kf1, 10, GEOMETRY, 3.0, merge=True) == 0
    assert (kf1.point_ids == before).all() and m.points.alive[dup].all()


def _map_room(neighbours: int) -> Map:
    """Track and map 40 frames of the synthetic room, a keyframe every 5, fusing over `neighbours` keyframes."""
    from dataclasses import replace

    from tests.worker.slam.synthetic_room import render, trajectory
    from worker.slam.presets import get_preset
    from worker.slam.run.parts import build_slam

    cfg = get_preset("orb-only")
    cfg = replace(cfg, mapping=replace(cfg.mapping, fuse_neighbours=neighbours),
                  tracking=replace(cfg.tracking, keyframe_max_frames=5))
    parts = build_slam(CAM, cfg)
    tr, mapper = parts.tracker, parts.mapper
    for i, T in enumerate(trajectory(40, yaw_span_deg=30)):
        res = tr.track(i, i / 30, *render(T))
        assert res.ok
        if res.keyframe is not None:
            mapper.process(res.keyframe)
    assert (mapper.fused > 0) == (neighbours > 0)
    return tr.map


def _observations_per_point(m: Map) -> np.ndarray:
    ids = np.concatenate([kf.point_ids for kf in m.keyframes])
    ids = ids[ids >= 0]
    return np.bincount(ids, minlength=m.points.n)[m.points.alive[: m.points.n]]


def test_fusion_in_the_room_ties_keyframes_together():
    """Fusion gives the room's points more observing keyframes and the keyframes stronger covisibility, and
    every observation it adds reprojects onto its keypoint (it passed the chi-square test)."""
    off, on = _map_room(0), _map_room(10)
    # measured: 2.47 -> 2.60 observing keyframes per point, covisibility weight 233 -> 259 on average
    assert _observations_per_point(on).mean() > 1.03 * _observations_per_point(off).mean()
    assert np.mean([w for nb in on.covis.values() for w in nb.values()]) > \
        1.05 * np.mean([w for nb in off.covis.values() for w in nb.values()])
    for kf in on.keyframes:
        has = np.flatnonzero(kf.point_ids >= 0)
        alive = has[on.points.alive[kf.point_ids[has]]]
        T = inv(kf.T_WC)
        Pc = on.points.pos[kf.point_ids[alive]] @ T[:3, :3].T + T[:3, 3]
        uv = Pc[:, :2] / Pc[:, 2:] * [CAM.fx, CAM.fy] + [CAM.cx, CAM.cy]
        assert np.median(np.linalg.norm(uv - kf.feats.uv[alive], axis=1)) < 1.0
