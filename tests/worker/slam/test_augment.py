"""Augmented-real generator: people cut from polygon labels, standing on the floor, exact truth vs the source."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from worker.slam.augment.floor import estimate_floor, gravity_up
from worker.slam.augment.generator import AugmentConfig, AugmentedSequence, generate_augmented
from worker.slam.augment.sprites import load_sprites
from worker.slam.io.sequence import Sequence
from worker.slam.synth.generator import SynthConfig, generate_synthetic
from worker.slam.truth import load_truth


def make_coco(root, rng):
    """A YOLO-seg folder with one whole-body 'person', one clipped person, one chair, one label without image."""
    (root / "images/train2017").mkdir(parents=True)
    (root / "labels/train2017").mkdir(parents=True)
    img = rng.integers(0, 255, (480, 640, 3), dtype=np.uint8)
    cv2.rectangle(img, (250, 60), (350, 420), (40, 60, 200), -1)
    cv2.imwrite(str(root / "images/train2017/000000000001.jpg"), img)
    body = np.array([[300, 60], [340, 100], [350, 250], [330, 420], [270, 420], [250, 250], [260, 100]], float)
    clipped = np.array([[0, 100], [60, 100], [60, 470], [0, 470]], float)
    norm = lambda p: " ".join(f"{v:.5f}" for v in (p / [640, 480]).ravel())  # noqa: E731
    (root / "labels/train2017/000000000001.txt").write_text(
        f"0 {norm(body)}\n0 {norm(clipped)}\n56 {norm(body)}\n")
    (root / "labels/train2017/000000000002.txt").write_text(f"0 {norm(body)}\n")
    return root


@pytest.fixture(scope="module")
def static_source(tmp_path_factory):
    """A static synthetic sequence (no walkers) with ground truth: the stand-in for a real static recording."""
    root = tmp_path_factory.mktemp("static")
    generate_synthetic(root, SynthConfig(frames=30, people=0, trajectory="circle", seed=2))
    return root


def test_sprites_keep_whole_upright_people_only(tmp_path):
    sprites = load_sprites(make_coco(tmp_path, np.random.default_rng(0)))
    assert len(sprites) == 1
    s = sprites[0]
    assert s.mask.shape == s.rgb.shape[:2] and s.mask.dtype == np.uint8
    assert 300 <= s.mask.shape[0] <= 365 and s.aspect < 0.5
    assert s.bulge.max() == pytest.approx(1.0) and s.bulge[s.mask == 0].max() == 0


def test_floor_from_points_and_gravity():
    rng = np.random.default_rng(0)
    pitch = np.radians(25)  # cameras looking down at a table
    R = np.array([[1, 0, 0], [0, -np.sin(pitch), np.cos(pitch)], [0, -np.cos(pitch), -np.sin(pitch)]])
    poses = np.tile(np.eye(4), (20, 1, 1))
    poses[:, :3, :3] = R
    poses[:, :3, 3] = np.c_[rng.uniform(-1, 1, (20, 2)), np.full(20, 1.5)]
    rough = gravity_up(poses)  # from the cameras alone: tilted by their pitch
    assert np.degrees(np.arccos(rough[2])) > 20
    normals = np.concatenate([np.tile([0.0, 0, 1], (3000, 1)), np.tile([0.0, -1, 0], (3000, 1))])
    normals += 0.05 * rng.standard_normal(normals.shape)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    up = gravity_up(poses, normals)
    assert np.degrees(np.arccos(up[2])) < 1.0
    floor = rng.uniform(-3, 3, (3000, 3)) * [1, 1, 0] + [0, 0, 0.01] * rng.standard_normal((3000, 1))
    table = rng.uniform(-0.5, 0.5, (20000, 3)) * [1, 1, 0] + [0, 0, 0.75]
    wall = np.c_[rng.uniform(-3, 3, 8000), np.full(8000, 3.0), rng.uniform(0, 2.5, 8000)]
    f = estimate_floor(np.concatenate([floor, table, wall]), poses, np.array([0.0, 0, 1]))
    assert abs(f.height) < 0.02 and f.inliers > 1000
    assert np.allclose(f.project(np.array([0.3, 0.2, 1.7])), [0.3, 0.2, f.height])


def test_augmented_truth_is_exact(static_source, tmp_path):
    coco = make_coco(tmp_path / "coco", np.random.default_rng(1))
    out = tmp_path / "aug"
    res = generate_augmented(static_source, coco, out, AugmentConfig(frames=30, people=2, seed=4))
    src, seq, truth = Sequence(static_source), Sequence(out), load_truth(out)
    assert truth is not None and len(seq) == len(truth) == 30
    assert abs(res.floor.height) < 0.03 and res.floor.up[2] > 0.99  # the synthetic floor is z = 0
    assert np.allclose(seq.groundtruth.poses, src.groundtruth.poses)
    seen = 0
    for i in range(0, 30, 2):
        a, s, m = seq[i], src[i], truth.mask(i)
        assert np.array_equal(a.rgb[~m], s.rgb[~m]) and np.array_equal(a.depth[~m], s.depth[~m])
        assert np.array_equal(truth.background_rgb(i), s.rgb)
        assert np.array_equal(truth.background_depth(i), s.depth)
        if m.any():
            seen += 1
            behind = s.depth[m]
            assert np.all((behind == 0) | (a.depth[m] <= behind))  # people only where they are in front
    assert seen >= 3 and max(res.dynamic_fraction) > 0.02
    assert (out / "truth/background_rgb/000000.png").read_bytes() == (static_source / "rgb/000000.png").read_bytes()


@pytest.mark.realdata
def test_redkitchen_people_stand_on_the_floor(redkitchen, shared, tmp_path):
    coco = shared / "data" / "coco128_seg"
    if not (coco / "labels").is_dir():
        pytest.skip(f"{coco} not present")
    aug = AugmentedSequence(redkitchen, coco, AugmentConfig(frames=120, people=2, seed=0))
    assert len(aug.sprites) >= 10
    heights = aug.poses[:, :3, 3] @ aug.floor.up - aug.floor.height
    assert 1.1 < heights.mean() < 1.8  # a hand-held camera above the kitchen floor
    res = generate_augmented(redkitchen, coco, tmp_path, AugmentConfig(frames=120, people=2, seed=0))
    seq, truth = Sequence(tmp_path), load_truth(tmp_path)
    for i in (0, 60, 119):
        m = truth.mask(i)
        assert np.array_equal(seq[i].rgb[~m], truth.background_rgb(i)[~m])
        assert np.array_equal(seq[i].depth[~m], truth.background_depth(i)[~m])
    assert np.mean(np.array(res.dynamic_fraction) > 0.02) > 0.5
