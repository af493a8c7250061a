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
