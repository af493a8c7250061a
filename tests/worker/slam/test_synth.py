"""Synthetic generator: files re-read exactly, truth exact by construction, trackable texture, sensor model."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from worker.slam.errors import ConfigError
from worker.slam.io.sequence import Sequence
from worker.slam.io.trajectory import Trajectory, read_tum_trajectory, write_tum_trajectory
from worker.slam.synth.generator import SynthConfig, SyntheticWorld, generate_synthetic
from worker.slam.synth.kinect import KinectConfig, KinectSensor
from worker.slam.synth.paths import walk_path
from worker.slam.truth import load_truth

N = 16


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    root = tmp_path_factory.mktemp("synth")
    cfg = SynthConfig(frames=N, people=2, trajectory="walk", seed=3)
    return root, cfg, generate_synthetic(root, cfg)


def test_layout_and_camera_path_reread(synth):
    root, cfg, result = synth
    seq = Sequence(root)  # camera.json in the folder is enough
    assert len(seq) == N and seq.camera.name == "synthetic" and seq.camera.depth_scale == 5000
    assert seq.groundtruth is not None
    idx, poses = seq.groundtruth_for_frames()
    assert np.array_equal(idx, np.arange(N))
    assert np.abs(poses[:, :3, 3] - result.trajectory.poses[:, :3, 3]).max() < 1e-6
    assert np.abs(poses[:, :3, :3] - result.trajectory.poses[:, :3, :3]).max() < 1e-6


def test_truth_is_exact_by_construction(synth):
    root, cfg, result = synth
    seq, truth = Sequence(root), load_truth(root)
    world = SyntheticWorld(cfg)
    assert truth is not None and len(truth) == N
    assert np.allclose(truth.timestamps, seq.timestamps, atol=1e-9)
    covered = 0
    for i in range(0, N, 3):
        f, t = seq[i], truth[i]
        m = t.mask
        # Outside the mask the frame *is* the background, colour and depth, bit for bit.
        assert np.array_equal(f.rgb[~m], t.background_rgb[~m])
        assert np.array_equal(f.depth[~m], t.background_depth[~m])
        # Background + dynamic pixels composite back to the frame exactly.
        comp_rgb = np.where(m[..., None], f.rgb, t.background_rgb)
        comp_depth = np.where(m, f.depth, t.background_depth)
        assert np.array_equal(comp_rgb, f.rgb) and np.array_equal(comp_depth, f.depth)
        # The background is the static scene rendered alone; the mask is where walkers are visible.
        out = world.renderer.render(world.T_RW @ world.trajectory.poses[i],
                                    [w.parts(float(seq.timestamps[i] - seq.timestamps[0])) for w in world.walkers])
        assert np.array_equal(t.background_rgb, out.static_rgb)
        assert np.array_equal(t.ids, out.ids)
        if m.any():
            covered += 1
            assert (f.rgb[m] != t.background_rgb[m]).any(axis=1).mean() > 0.9
            nearer = f.depth[m][(f.depth[m] > 0) & (t.background_depth[m] > 0)]
            assert np.median(nearer) < np.median(t.background_depth[m][t.background_depth[m] > 0])
    assert covered >= 3


def test_people_move_and_cover_a_sensible_share(synth):
    _, _, result = synth
    fr = np.array(result.dynamic_fraction)
    assert 0.01 < fr.mean() < 0.5
    truth = load_truth(synth[0])
    c0 = np.argwhere(truth.mask(0)).mean(axis=0)
    c1 = np.argwhere(truth.mask(N - 1)).mean(axis=0)
    assert np.linalg.norm(c0 - c1) > 5  # pixels


def test_orb_finds_plenty_of_features(synth):
    seq = Sequence(synth[0])
    orb = cv2.ORB_create(1000)
    for i in (0, N // 2, N - 1):
        grey = cv2.cvtColor(seq[i].rgb, cv2.COLOR_RGB2GRAY)
        assert len(orb.detect(grey, None)) >= 500


def test_depth_looks_like_a_kinect(synth):
    seq = Sequence(synth[0])
    d = seq[0].depth
    holes = (d == 0).mean()
    assert 0.005 < holes < 0.3
    assert d.max() <= 5.0 and d[d > 0].min() >= 0.45


def test_quantisation_grows_with_range():
    sensor = KinectSensor(KinectConfig(), (1, 4000))
    z = np.linspace(0.8, 4.5, 4000, dtype=np.float32)[None, :]
    q = sensor.measure(z, np.zeros_like(z))[0]
    step = lambda lo, hi: np.diff(np.unique(q[(q > lo) & (q < hi)])).mean()  # noqa: E731
    assert step(0.9, 1.1) < 0.005 and step(3.8, 4.2) > 10 * step(0.9, 1.1)
    assert np.abs(q - z[0]).max() < 0.05


def test_deterministic_per_seed():
    a = SyntheticWorld(SynthConfig(frames=3, people=1, trajectory="circle", seed=5)).frame(2)
    b = SyntheticWorld(SynthConfig(frames=3, people=1, trajectory="circle", seed=5)).frame(2)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth) and np.array_equal(a.ids, b.ids)


def test_replay_of_a_trajectory_file_keeps_poses(tmp_path):
    src = walk_path(200, np.random.default_rng(1), fps=100.0)  # a 100 Hz recording, like TUM's mocap
    src = Trajectory(src.timestamps + 1341846313.6378, src.poses)
    write_tum_trajectory(tmp_path / "gt.txt", src)
    original = read_tum_trajectory(tmp_path / "gt.txt")
    out = tmp_path / "seq"
    res = generate_synthetic(out, SynthConfig(frames=5, people=0, trajectory=str(tmp_path / "gt.txt")))
    back = read_tum_trajectory(out / "groundtruth.txt")
    j = np.searchsorted(original.timestamps, back.timestamps - 1e-7)
    assert np.abs(original.timestamps[j] - back.timestamps).max() < 1e-6
    assert np.abs(original.positions[j] - back.positions).max() < 1e-6
    assert np.allclose(np.diff(back.timestamps), 0.03, atol=0.011)  # ~30 Hz from 100 Hz
    assert load_truth(out) is not None and res.frames == 5


def test_bad_config_is_a_domain_error(tmp_path):
    with pytest.raises(ConfigError):
        SyntheticWorld(SynthConfig(frames=2, trajectory=str(tmp_path / "missing.txt")))
    with pytest.raises(ConfigError):
        SyntheticWorld(SynthConfig(frames=0))


@pytest.mark.realdata
def test_default_replays_tum_walking_xyz(shared, tmp_path):
    gt_file = shared / "data/trajectories/tum_fr3_walking_xyz/groundtruth.txt"
    if not gt_file.is_file():
        pytest.skip(f"{gt_file} not present")
    res = generate_synthetic(tmp_path, SynthConfig(frames=6, people=1, shared_dir=shared))
    assert res.source.startswith("replay:")
    src = read_tum_trajectory(gt_file)
    back = read_tum_trajectory(tmp_path / "groundtruth.txt")
    j = np.searchsorted(src.timestamps, back.timestamps - 1e-7)
    assert np.abs(src.timestamps[j] - back.timestamps).max() < 1e-6
    assert np.abs(src.positions[j] - back.positions).max() < 1e-6
