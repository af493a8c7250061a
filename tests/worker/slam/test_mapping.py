"""Map points, covisibility, local BA, culling, dense fusion and the PLY writer."""
from __future__ import annotations

import numpy as np
import pytest

from formats.ply import read_ply, write_ply
from tests.worker.slam.synthetic_room import K_SYN, render, trajectory
from worker.slam.camera import Camera
from worker.slam.config import MappingConfig
from worker.slam.geometry.se3 import exp_se3, inv, pose_distance
from worker.slam.map.map import Map
from worker.slam.mapping.dense import fuse_keyframes, voxel_filter
from worker.slam.mapping.local_ba import local_bundle_adjust
from worker.slam.mapping.local_mapping import cull_points
from worker.slam.presets import get_preset
from worker.slam.run.parts import build_slam

CAM = Camera(525.0, 525.0, 319.5, 239.5, 5000.0, name="synthetic")


@pytest.fixture(scope="module")
def mapped():
    """A map built by the tracker (no local BA) on a room sequence with frequent keyframes."""
    cfg = get_preset("orb-only", {"tracking.keyframe_max_frames": 4})
    poses = trajectory(30, yaw_span_deg=30)
    tr = build_slam(CAM, cfg).tracker
    for i, T in enumerate(poses):
        rgb, depth = render(T)
        tr.track(i, i / 30, rgb, depth)
    return tr, inv(poses[0]) @ poses


def test_map_points_and_covisibility(mapped):
    tr, _ = mapped
    m = tr.map
    assert len(m) >= 5 and m.points.n_alive > 1000
    # consecutive keyframes share many points; the graph is symmetric
    assert m.covis[1][0] > 100 and m.covis[0][1] == m.covis[1][0]
    best = m.best_covisible(2, 2)
    assert set(best) <= {0, 1, 3, 4} and len(best) == 2


def test_local_ba_pulls_perturbed_keyframes_back(mapped):
    tr, gt = mapped
    m = tr.map
    saved = [kf.T_WC.copy() for kf in m.keyframes]
    saved_pts = m.points.pos.copy()
    saved_ids = [kf.point_ids.copy() for kf in m.keyframes]
    local = [len(m) - 1, len(m) - 2, len(m) - 3]
    orig = [pose_distance(m.keyframes[i].T_WC, gt[m.keyframes[i].frame_index])[0] for i in local]
    rng = np.random.default_rng(0)
    for i in local:
        m.keyframes[i].T_WC = m.keyframes[i].T_WC @ exp_se3(np.r_[rng.normal(0, 0.01, 3), rng.normal(0, 0.005, 3)])
    before = [pose_distance(m.keyframes[i].T_WC, gt[m.keyframes[i].frame_index])[0] for i in local]
    stats = local_bundle_adjust(m, local, K_SYN, tr.sensor.bf, tr.sensor.inv_sigma2, iterations=10)
    after = [pose_distance(m.keyframes[i].T_WC, gt[m.keyframes[i].frame_index])[0] for i in local]
    assert stats is not None and stats.fixed > 0 and stats.cost_after < stats.cost_before
    assert np.mean(after) < 0.5 * np.mean(before) and np.mean(after) <= np.mean(orig) + 0.001
    for kf, T, ids in zip(m.keyframes, saved, saved_ids):  # restore for the other tests
        kf.T_WC, kf.point_ids = T, ids
    m.points.pos[:] = saved_pts


def test_local_ba_blocks_are_the_numpy_expressions_bit_for_bit():
    """The compiled normal-equation blocks against the einsum / add.at expressions they replace (points behind a
    camera, observations without depth, fixed cameras, points seen many times): equal bits."""
    from scipy.spatial.transform import Rotation

    from worker.slam.geometry import reprojection as rp
    from worker.slam.mapping.local_ba import _normal_blocks
    rng = np.random.default_rng(4)
    n, n_var, ncam, P, bf = 3000, 6, 9, 700, 40.0
    T_CW = np.tile(np.eye(4), (ncam, 1, 1))
    T_CW[:, :3, :3] = Rotation.random(ncam, random_state=2).as_matrix()
    c, p = rng.integers(0, ncam, n), rng.integers(0, P, n)
    Pc = np.column_stack([rng.normal(0, 1, n), rng.normal(0, 1, n), rng.uniform(0.3, 5, n)])
    Pc[:15, 2] = -0.5
    front = Pc[:, 2] > 1e-3
    e, roww = rng.normal(0, 2, (n, 3)), np.ones((n, 3))
    roww[rng.random(n) < 0.2, 2] = 0.0
    w = rng.uniform(0, 2, n) * front
    Jp = rp.jacobian_point(np.where(front[:, None], Pc, 1.0), K_SYN, bf) * roww[:, :, None]
    JX = Jp @ T_CW[c, :3, :3]
    var = c < n_var
    Jc = rp.jacobian_pose(Pc[var], Jp[var])
    want = [np.zeros((n_var, 6, 6)), np.zeros((n_var, 6)), np.zeros((P, 3, 3)), np.zeros((P, 3))]
    np.add.at(want[0], c[var], np.einsum("nik,n,nil->nkl", Jc, w[var], Jc))
    np.add.at(want[1], c[var], np.einsum("nik,n,ni->nk", Jc, w[var], e[var]))
    np.add.at(want[2], p, np.einsum("nik,n,nil->nkl", JX, w, JX))
    np.add.at(want[3], p, np.einsum("nik,n,ni->nk", JX, w, e))
    want.append(np.einsum("nik,n,nil->nkl", Jc, w[var], JX[var]))
    for got, ref in zip(_normal_blocks(Pc, Jp, JX, w, e, c, p, n_var, P), want):
        assert got.shape == ref.shape and np.array_equal(got, ref)


def test_culling_removes_unconfirmed_recent_points():
    m = Map()
    p = m.points
    ids = p.add(np.random.rand(4, 3) + [0, 0, 2], np.zeros((4, 32), np.uint8), np.zeros(3), np.zeros(4, int), 1.2, 0)
    p.visible[ids] = [10, 10, 10, 10]
    p.found[ids] = [9, 1, 9, 9]      # point 1 is rarely found
    p.n_obs[ids] = [3, 3, 1, 3]      # point 2 never seen by a second keyframe
    assert cull_points(m, 2, MappingConfig()) == 2
    assert list(p.alive[ids]) == [True, False, False, True]


def test_dense_fusion_and_ply_roundtrip(mapped, tmp_path):
    tr, _ = mapped
    m = tr.map
    xyz, rgb = fuse_keyframes(m.keyframes, K_SYN, 4, 0.02, 6.0)
    assert len(xyz) > 1000 and xyz.dtype == np.float32 and rgb.dtype == np.uint8
    # every fused point lies on the room's walls (first camera frame == world of the tracker here)
    from tests.worker.slam.synthetic_room import HALF
    gt0 = trajectory(30, yaw_span_deg=30)[0]
    Xw = xyz @ gt0[:3, :3].T + gt0[:3, 3]
    wall = np.min(np.abs(np.abs(Xw) - HALF), axis=1)
    assert np.median(wall) < 0.01
    path = tmp_path / "map.ply"
    write_ply(path, xyz, rgb)
    assert path.read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\n")
    x2, c2 = read_ply(path)
    assert np.array_equal(x2, xyz) and np.array_equal(c2, rgb)


def test_voxel_filter_merges_close_points():
    xyz = np.array([[0.001, 0.001, 0.001], [0.002, 0.002, 0.002], [0.5, 0.5, 0.5]])
    rgb = np.array([[0, 0, 0], [200, 200, 200], [10, 20, 30]], np.uint8)
    x, c = voxel_filter(xyz, rgb, 0.01)
    assert len(x) == 2 and [100, 100, 100] in c.tolist()


def test_depth_edges_flag_silhouettes_and_holes():
    from worker.slam.mapping.dense import depth_edges

    d = np.full((20, 20), 2.0, np.float32)
    d[:, 10:] = 1.0  # a silhouette
    d[2, 2] = 0.0  # a hole
    e = depth_edges(d, 0.05)
    assert e[:, 9:11].all() and not e[:, 5].any()
    assert e[1:4, 1:4].all() and not e[10, 15]
