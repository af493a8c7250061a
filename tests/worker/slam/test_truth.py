"""Truth layout (write, lazy read, validation) and the scores the dynamic stages are judged by."""
from __future__ import annotations

import json

import numpy as np
import pytest

from worker.slam.camera import PRESETS
from worker.slam.errors import SequenceFormatError
from worker.slam.io.sequence import Sequence
from worker.slam.io.trajectory import Trajectory
from worker.slam.synth.writer import SequenceWriter, depth_to_png
from worker.slam.truth import (
    feature_precision_recall,
    load_truth,
    mask_iou,
    restoration_psnr,
    write_background_sequence,
)


def test_mask_iou():
    a = np.zeros((4, 4), bool)
    b = np.zeros((4, 4), bool)
    assert mask_iou(a, b) == 1.0  # nothing to find, nothing found
    a[:2] = True
    b[1:3] = True
    assert mask_iou(a, b) == pytest.approx(4 / 12)
    assert mask_iou(a, a) == 1.0
    with pytest.raises(ValueError):
        mask_iou(a, np.zeros((3, 4), bool))


def test_feature_precision_recall():
    mask = np.zeros((10, 10), bool)
    mask[:, :5] = True  # left half dynamic
    removed = np.array([[1.0, 1.0], [2.2, 8.0], [7.0, 3.0]])  # 2 on dynamic, 1 on static
    kept = np.array([[3.0, 3.0], [8.0, 8.0], [9.6, 9.6]])  # 1 dynamic left behind; last is clipped to (9, 9)
    pr = feature_precision_recall(removed, kept, mask)
    assert (pr.tp, pr.fp, pr.fn) == (2, 1, 1)
    assert pr.precision == pytest.approx(2 / 3) and pr.recall == pytest.approx(2 / 3)
    empty = feature_precision_recall(np.zeros((0, 2)), np.array([[8.0, 8.0]]), mask)
    assert empty.precision == 1.0 and empty.recall == 1.0


def test_restoration_psnr():
    bg = np.full((8, 8, 3), 100, np.uint8)
    out = bg.copy()
    region = np.zeros((8, 8), bool)
    region[2:4, 2:4] = True
    assert restoration_psnr(out, bg, region) == float("inf")
    out[2:4, 2:4] += 10
    out[6, 6] = 0  # outside the region: ignored
    assert restoration_psnr(out, bg, region) == pytest.approx(10 * np.log10(255**2 / 100))
    assert np.isnan(restoration_psnr(out, bg, np.zeros((8, 8), bool)))


def _write_tiny(root, n=3):
    cam = PRESETS["tum3"]
    w = SequenceWriter(root, cam)
    rng = np.random.default_rng(0)
    frames = []
    for i in range(n):
        bg = rng.integers(0, 255, (cam.height, cam.width, 3), dtype=np.uint8)
        bgd = depth_to_png(rng.uniform(0.5, 4, (cam.height, cam.width)).astype(np.float32), cam.depth_scale)
        ids = np.zeros((cam.height, cam.width), np.uint8)
        ids[100:200, 50 + 40 * i:150 + 40 * i] = 1
        rgb, d = bg.copy(), bgd.copy()
        rgb[ids > 0] = 255
        d[ids > 0] = 5000
        w.add(i / 30, rgb, d, ids, bg, bgd)
        frames.append((rgb, d, ids, bg, bgd))
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.arange(n) * 0.01
    w.finish(Trajectory(np.arange(n) / 30, poses), [{"id": 1, "class": "person"}], {"name": "test"})
    return frames


def test_roundtrip_layout(tmp_path):
    assert load_truth(tmp_path) is None  # a real sequence without truth
    frames = _write_tiny(tmp_path)
    truth = load_truth(tmp_path)
    assert truth is not None and len(truth) == 3
    assert np.allclose(truth.timestamps, np.arange(3) / 30, atol=1e-6)
    meta = json.loads((tmp_path / "truth" / "truth.json").read_text())
    assert meta["objects"] == [{"id": 1, "class": "person"}] and meta["version"] == 1
    for i, (_, _, ids, bg, bgd) in enumerate(frames):
        f = truth[i]
        assert np.array_equal(f.ids, ids) and np.array_equal(f.mask, ids > 0)
        assert np.array_equal(f.background_rgb, bg)
        assert np.array_equal(f.background_depth, bgd.astype(np.float32) / 5000)
    with pytest.raises(IndexError):
        truth.ids(3)


def test_background_sequence_holds_the_frames_without_their_objects(tmp_path):
    frames = _write_tiny(tmp_path / "seq")
    with pytest.raises(SequenceFormatError, match="no truth"):
        write_background_sequence(tmp_path / "bg", tmp_path / "none")  # a folder without truth
    bg = Sequence(write_background_sequence(tmp_path / "seq", tmp_path / "bg"), PRESETS["tum3"])
    own = Sequence(tmp_path / "seq", PRESETS["tum3"])
    assert len(bg) == 3 and np.array_equal(bg.timestamps, own.timestamps)
    assert bg.groundtruth is not None and np.allclose(bg.groundtruth.poses, own.groundtruth.poses)
    for i, (rgb, _, ids, background, background_depth) in enumerate(frames):
        f = bg[i]
        assert np.array_equal(f.rgb, background) and not np.array_equal(f.rgb, rgb)
        assert np.array_equal(f.depth, background_depth.astype(np.float32) / 5000)
        assert np.array_equal(load_truth(tmp_path / "bg").mask(i), ids > 0)  # masks: where the objects were


def test_invalid_truth_json_is_reported(tmp_path):
    (tmp_path / "truth").mkdir()
    (tmp_path / "truth" / "truth.json").write_text("{not json")
    with pytest.raises(SequenceFormatError, match="truth.json"):
        load_truth(tmp_path)
    (tmp_path / "truth" / "truth.json").write_text(json.dumps({"version": 99}))
    with pytest.raises(SequenceFormatError, match="version"):
        load_truth(tmp_path)
    (tmp_path / "truth" / "truth.json").write_text(json.dumps(
        {"version": 1, "frames": 2, "timestamps": [0.0], "depth_scale": 5000}))
    with pytest.raises(SequenceFormatError, match="disagree"):
        load_truth(tmp_path)


def test_scores_accumulate_over_frames(tmp_path):
    from worker.slam.truth import TruthScores

    frames = _write_tiny(tmp_path)
    scores = TruthScores(load_truth(tmp_path))
    assert scores.summary()["mask_iou"] is None
    for i, (rgb, _, ids, bg, _) in enumerate(frames):
        assert scores.add_mask(i, ids > 0) == 1.0
        ys, xs = np.nonzero(ids)
        removed = np.c_[xs[:5], ys[:5]].astype(float)
        kept = np.array([[5.0, 5.0]])
        scores.add_features(i, removed, kept)
        restored = np.where((ids > 0)[..., None], bg, rgb)
        assert scores.add_restoration(i, restored, ids > 0) == float("inf")
    s = scores.summary()
    assert s["mask_iou"] == 1.0 and s["feature_precision"] == 1.0 and s["feature_recall"] == 1.0
    assert s["restoration_psnr"] == 100.0 and s["frames_scored"] == {"mask": 3, "restoration": 3}


def test_kept_dynamic_keypoints_split_into_culling_and_segmentation_misses(tmp_path):
    """Of the keypoints on the truth mask, the kept ones that segmentation had marked are culling's misses, the
    unmarked ones segmentation's; with the removed ones they are every dynamic keypoint."""
    from worker.slam.truth import TruthScores

    frames = _write_tiny(tmp_path)
    ids = frames[0][2]
    ys, xs = np.nonzero(ids)
    on = np.c_[xs, ys].astype(float)[:6]  # six keypoints on the mover
    marked = np.zeros(ids.shape, bool)
    marked[ys[0], xs[0]] = marked[ys[1], xs[1]] = True  # segmentation marked two of the kept four
    scores = TruthScores(load_truth(tmp_path))
    scores.add_features(0, on[4:], np.r_[on[:4], [[5.0, 5.0]]], marked=marked)
    s = scores.summary()
    assert s["feature_recall"] == pytest.approx(2 / 6)
    assert s["feature_missed_by_culling"] == pytest.approx(2 / 6)
    assert s["feature_missed_by_segmentation"] == pytest.approx(2 / 6)
    plain = TruthScores(load_truth(tmp_path))
    plain.add_features(0, on[4:], on[:4])
    assert "feature_missed_by_culling" not in plain.summary()  # no segmentation, no split
