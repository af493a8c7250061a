"""Carving the point map: what later keyframes see through goes, what they see (or only occlude) stays."""
from __future__ import annotations

import numpy as np

from tests.worker.slam.mapping.test_tsdf import STRIDE, K, _kf, _near
from worker.slam.mapping.carve import FrameViews, carve, keyframe_views
from worker.slam.mapping.dense import fuse_keyframes


def test_a_box_later_keyframes_see_through_is_carved_and_the_wall_stays() -> None:
    kfs = [_kf(i, 0.02 * i, box=i < 2) for i in range(8)]
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    kept, kept_rgb = carve(xyz, rgb, keyframe_views(kfs), K, STRIDE)
    assert _near(xyz, 1.0) > 100 and _near(kept, 1.0) == 0
    assert _near(kept, 2.0) == _near(xyz, 2.0)  # the wall was occluded by the box, never seen through
    assert len(kept_rgb) == len(kept)


def test_a_box_that_stays_is_kept_even_where_the_mask_removed_it() -> None:
    # the box is always there but was masked out of the fused depth in the last keyframes: the measured
    # depth still sees it, so nothing is seen through
    kfs = [_kf(i, 0.02 * i, box=True) for i in range(8)]
    for kf in kfs[2:]:
        assert kf.depth_small is not None  # _kf keeps its dense images
        kf.depth_small = np.where(kf.depth_small < 1.5, 0, kf.depth_small).astype(np.float32)
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    kept, _ = carve(xyz, rgb, keyframe_views(kfs), K, STRIDE)
    assert _near(kept, 1.0) == _near(xyz, 1.0) > 100


def test_one_view_through_a_point_is_not_enough() -> None:
    kfs = [_kf(i, 0.02 * i, box=i < 7) for i in range(8)]  # only the last keyframe sees the wall behind
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    kept, _ = carve(xyz, rgb, keyframe_views(kfs), K, STRIDE)
    assert _near(kept, 1.0) == _near(xyz, 1.0)


def test_a_box_that_lingers_then_leaves_is_carved_unless_the_majority_rule_is_asked_for() -> None:
    # seen by five keyframes, seen through by the three after it left (a person who stayed in view a while)
    kfs = [_kf(i, 0.02 * i, box=i < 5) for i in range(8)]
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    assert _near(xyz, 1.0) > 100
    kept, _ = carve(xyz, rgb, keyframe_views(kfs), K, STRIDE)
    assert _near(kept, 1.0) == 0
    assert _near(kept, 2.0) == _near(xyz, 2.0)
    kept_majority, _ = carve(xyz, rgb, keyframe_views(kfs), K, STRIDE, majority=True)
    assert _near(kept_majority, 1.0) == _near(xyz, 1.0)


def test_a_box_seen_through_before_it_came_is_carved() -> None:
    # the wall is seen free by the first three keyframes, then something stands in front of it to the end
    kfs = [_kf(i, 0.02 * i, box=i >= 3) for i in range(8)]
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    kept, _ = carve(xyz, rgb, keyframe_views(kfs), K, STRIDE)
    assert _near(xyz, 1.0) > 100 and _near(kept, 1.0) == 0


def test_min_through_sets_how_many_views_must_see_through() -> None:
    kfs = [_kf(i, 0.02 * i, box=i < 6) for i in range(8)]  # two keyframes see the wall behind
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    assert _near(carve(xyz, rgb, keyframe_views(kfs), K, STRIDE, min_through=2)[0], 1.0) == 0
    assert _near(carve(xyz, rgb, keyframe_views(kfs), K, STRIDE, min_through=3)[0], 1.0) == _near(xyz, 1.0)


def test_frames_between_keyframes_vote_at_their_poses() -> None:
    # the keyframes alone (box seen by all but one) keep the box; frames in between that see the wall behind it
    # carve it
    kfs = [_kf(i, 0.02 * i, box=i < 7) for i in range(8)]
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    assert _near(carve(xyz, rgb, keyframe_views(kfs), K, STRIDE)[0], 1.0) == _near(xyz, 1.0)
    frames = FrameViews(every=1, stride=1, max_views=100)
    poses = []
    for k in range(6):  # full-resolution frames: the keyframes' small images stand in for them (stride 1)
        kf = _kf(k, 0.01 + 0.02 * k, box=False)
        assert kf.measured_small is not None
        frames.offer(k, kf.measured_small)
        poses.append(kf.T_WC)
    views = frames.views(np.stack(poses), np.ones(6, bool))
    assert len(views) == 6
    assert _near(carve(xyz, rgb, views, K, STRIDE)[0], 1.0) == 0
    # untracked frames do not vote
    assert frames.views(np.stack(poses), np.zeros(6, bool)) == []


def test_frame_views_keep_every_nth_and_thin_past_the_cap() -> None:
    frames = FrameViews(every=2, stride=2, max_views=4)
    depth = np.ones((8, 8), np.float32)
    for k in range(10):
        frames.offer(k, depth * k)
    # kept 0, 2, 4, 6, 8 -> five exceed the cap: every 4th frame from then on
    assert frames.every == 4 and sorted(frames.depth) == [0, 4, 8]
    assert frames.depth[4].shape == (4, 4) and float(frames.depth[4][0, 0]) == 4.0
    assert FrameViews(every=0, stride=1, max_views=4).views(np.zeros((0, 4, 4)), np.zeros(0, bool)) == []
