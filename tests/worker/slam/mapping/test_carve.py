"""Carving the point map: what later keyframes see through goes, what they see (or only occlude) stays."""
from __future__ import annotations

import numpy as np

from tests.worker.slam.mapping.test_tsdf import STRIDE, K, _kf, _near
from worker.slam.mapping.carve import carve
from worker.slam.mapping.dense import fuse_keyframes


def test_a_box_later_keyframes_see_through_is_carved_and_the_wall_stays() -> None:
    kfs = [_kf(i, 0.02 * i, box=i < 2) for i in range(8)]
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    kept, kept_rgb = carve(xyz, rgb, kfs, K, STRIDE)
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
    kept, _ = carve(xyz, rgb, kfs, K, STRIDE)
    assert _near(kept, 1.0) == _near(xyz, 1.0) > 100


def test_one_view_through_a_point_is_not_enough() -> None:
    kfs = [_kf(i, 0.02 * i, box=i < 7) for i in range(8)]  # only the last keyframe sees the wall behind
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    kept, _ = carve(xyz, rgb, kfs, K, STRIDE)
    assert _near(kept, 1.0) == _near(xyz, 1.0)


def test_a_box_that_lingers_then_leaves_is_carved_unless_the_majority_rule_is_asked_for() -> None:
    # seen by five keyframes, seen through by the three after it left (a person who stayed in view a while)
    kfs = [_kf(i, 0.02 * i, box=i < 5) for i in range(8)]
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    assert _near(xyz, 1.0) > 100
    kept, _ = carve(xyz, rgb, kfs, K, STRIDE)
    assert _near(kept, 1.0) == 0
    assert _near(kept, 2.0) == _near(xyz, 2.0)
    kept_majority, _ = carve(xyz, rgb, kfs, K, STRIDE, majority=True)
    assert _near(kept_majority, 1.0) == _near(xyz, 1.0)


def test_a_box_seen_through_before_it_came_is_carved() -> None:
    # the wall is seen free by the first three keyframes, then something stands in front of it to the end
    kfs = [_kf(i, 0.02 * i, box=i >= 3) for i in range(8)]
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    kept, _ = carve(xyz, rgb, kfs, K, STRIDE)
    assert _near(xyz, 1.0) > 100 and _near(kept, 1.0) == 0


def test_min_through_sets_how_many_views_must_see_through() -> None:
    kfs = [_kf(i, 0.02 * i, box=i < 6) for i in range(8)]  # two keyframes see the wall behind
    xyz, rgb = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    assert _near(carve(xyz, rgb, kfs, K, STRIDE, min_through=2)[0], 1.0) == 0
    assert _near(carve(xyz, rgb, kfs, K, STRIDE, min_through=3)[0], 1.0) == _near(xyz, 1.0)
