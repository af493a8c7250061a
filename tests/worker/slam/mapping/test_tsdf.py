"""TSDF fusion of keyframes: a surface seen by every view stays, one that later views see through is carved."""
from __future__ import annotations

import numpy as np

from worker.slam.features.types import Features
from worker.slam.map.keyframe import KeyFrame
from worker.slam.mapping.dense import fuse_keyframes
from worker.slam.mapping.tsdf import fuse_tsdf, volume_box

K = np.array([[525.0, 0, 319.5], [0, 525.0, 239.5], [0, 0, 1]])
STRIDE = 4


def _kf(i: int, x: float, box: bool) -> KeyFrame:
    """A camera at (x, 0, 0) looking along +z at a wall 2 m away; `box`: a 0.3 x 0.2 m block 1 m away,
    fixed in the world (its pixels shift as the camera moves)."""
    depth = np.full((120, 160), 2.0, np.float32)
    rgb = np.full((120, 160, 3), 200, np.uint8)
    if box:
        v, u = np.mgrid[0:120, 0:160] * STRIDE
        X = x + (u - K[0, 2]) / K[0, 0]  # where each pixel's ray crosses the plane z = 1 m
        Y = (v - K[1, 2]) / K[1, 1]
        on = (np.abs(X) < 0.15) & (np.abs(Y) < 0.1)
        depth[on] = 1.0
        rgb[on] = (255, 0, 0)
    T = np.eye(4)
    T[0, 3] = x
    return KeyFrame(i, i, float(i), T, Features.empty(), np.zeros(0, np.int64), rgb, depth, depth.copy())


def _near(xyz: np.ndarray, z: float) -> int:
    return int((np.abs(xyz[:, 2] - z) < 0.05).sum())


def test_a_surface_later_views_see_through_is_carved() -> None:
    # the "person" stands in front of the wall for two keyframes, then the wall behind it is seen six times
    kfs = [_kf(i, 0.02 * i, box=i < 2) for i in range(8)]
    points, _ = fuse_keyframes(kfs, K, STRIDE, 0.01, 4.0)
    xyz, rgb = fuse_tsdf(kfs, K, STRIDE, 0.01, 4.0)
    assert _near(points, 1.0) > 100  # the point map keeps the transient box
    assert _near(xyz, 1.0) == 0  # the volume carves it
    assert _near(xyz, 2.0) > 0.5 * _near(points, 2.0)  # and keeps the wall
    wall = np.abs(xyz[:, 2] - 2.0) < 0.05
    assert np.allclose(rgb[wall].mean(0), 200, atol=8)  # colours are the images' (RGB order kept)


def test_a_surface_every_view_sees_stays() -> None:
    kfs = [_kf(i, 0.02 * i, box=True) for i in range(6)]
    xyz, rgb = fuse_tsdf(kfs, K, STRIDE, 0.01, 4.0)
    box = np.abs(xyz[:, 2] - 1.0) < 0.05
    assert box.sum() > 100
    assert np.allclose(np.median(rgb[box], 0), (255, 0, 0), atol=10)  # (its rim blends with the wall)
    assert not (rgb == 0).all(1).any()  # no black specks where no colour sample reached


def test_points_come_in_a_reproducible_order() -> None:
    kfs = [_kf(i, 0.02 * i, box=True) for i in range(4)]
    xyz, rgb = fuse_tsdf(kfs, K, STRIDE, 0.01, 4.0)
    order = np.lexsort((xyz[:, 2], xyz[:, 1], xyz[:, 0]))
    assert np.array_equal(order, np.arange(len(xyz)))  # sorted by x, then y, then z (the volume's fetch is not)
    again, rgb_again = fuse_tsdf(kfs, K, STRIDE, 0.01, 4.0)
    assert np.array_equal(xyz, again) and np.array_equal(rgb, rgb_again)


def test_no_depth_gives_an_empty_map() -> None:
    kf = _kf(0, 0.0, box=False)
    kf.depth_small = np.zeros_like(kf.depth_small)
    xyz, rgb = fuse_tsdf([kf], K, STRIDE, 0.01, 4.0)
    assert xyz.shape == (0, 3) and rgb.shape == (0, 3)


def test_volume_box_coarsens_voxels_to_fit() -> None:
    pts = np.random.default_rng(0).uniform(-10, 10, (1000, 3))
    box = volume_box(pts, 0.01, 0.1)
    assert max(box.shape) <= 384 + 1 and box.voxel > 0.01
