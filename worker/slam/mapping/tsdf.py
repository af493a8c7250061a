"""Dense map by TSDF fusion (OpenCV 5's coloured TSDF volume) of the keyframes' strided RGB-D.

Why a volume instead of merged points: a TSDF stores, per voxel, a weighted mean of the signed distance to
the observed surface along every ray that passes through it, so a keyframe that sees *through* a place
(free space in front of its measured depth) pulls that voxel back to "empty". Whatever stood there for a
few keyframes and then left (a person that segmentation missed, a door that opened) is carved out by the
later views, while a point cloud keeps every surface it was ever shown.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from worker.slam.map.keyframe import KeyFrame
from worker.slam.mapping.dense import backproject_keyframe, depth_edges, pixel_rays

BORDER_PX = 2
"""Outer frame of the strided images left out of the volume."""
MAX_RESOLUTION = 384
"""Voxels along the longest side of the volume; a larger scene gets coarser voxels (memory ~ 4 B/voxel)."""


@dataclass(frozen=True)
class VolumeBox:
    """The axis-aligned box the volume covers, in the world frame: `origin` (3,) metres, `voxel` metres,
    `shape` (3,) voxels."""

    origin: np.ndarray
    voxel: float
    shape: tuple[int, int, int]


def volume_box(points_w: np.ndarray, voxel: float, margin: float) -> VolumeBox:
    """A box around the bulk of `points_w` (N,3) world points (0.5-99.5 percentiles, so a few far outliers
    cannot blow it up), grown by `margin`; voxels coarsened until it fits `MAX_RESOLUTION`."""
    lo = np.percentile(points_w, 0.5, axis=0) - margin
    hi = np.percentile(points_w, 99.5, axis=0) + margin
    voxel = max(voxel, float((hi - lo).max()) / MAX_RESOLUTION)
    shape = np.maximum(np.ceil((hi - lo) / voxel).astype(int), 1)
    return VolumeBox(lo.astype(np.float64), voxel, (int(shape[0]), int(shape[1]), int(shape[2])))


def undistort_small(kf: KeyFrame, K_small: np.ndarray, dist: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The keyframe's strided depth (h,w) float32 and RGB (h,w,3) uint8 resampled to the pinhole model the
    volume assumes (nearest neighbour: no depth is interpolated across a silhouette)."""
    assert kf.depth_small is not None and kf.rgb_small is not None
    if dist is None or not np.any(dist):
        return kf.depth_small, kf.rgb_small
    import cv2

    h, w = kf.depth_small.shape
    mx, my = cv2.initUndistortRectifyMap(K_small, np.asarray(dist, np.float64), None, K_small, (w, h), cv2.CV_32FC1)
    depth = cv2.remap(kf.depth_small, mx, my, cv2.INTER_NEAREST, borderValue=0)
    rgb = cv2.remap(kf.rgb_small, mx, my, cv2.INTER_NEAREST, borderValue=0)
    return depth, rgb


def fuse_tsdf(keyframes: list[KeyFrame], K: np.ndarray, stride: int, voxel: float, max_depth: float,
              dist: np.ndarray | None = None, edge_rel: float = 0.05,
              trunc_voxels: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """Surface points (M,3) float32 (world frame) and colours (M,3) uint8 RGB of the keyframes fused in a
    TSDF volume at their current `T_WC`.

    `K` 3x3 intrinsics of the full image; the keyframes hold every `stride`-th pixel. Depth beyond
    `max_depth` and at depth edges (`edge_rel`, as in the point map) is not integrated. The truncation band
    is `trunc_voxels` voxels: wide enough to absorb depth noise, narrow enough that thin structures survive.
    """
    kfs = [kf for kf in keyframes if kf.depth_small is not None and kf.rgb_small is not None]
    if not kfs:
        return _no_points()
    box = _keyframes_box(kfs, K, stride, voxel, max_depth, dist, edge_rel, margin=4 * trunc_voxels * voxel)
    if box is None:
        return _no_points()
    K_small = K.astype(np.float64).copy()
    K_small[:2] /= stride  # pixel (u, v) of the strided copy is (u*stride, v*stride) of the full image
    volume = _new_volume(box, K_small, kfs[0].depth_small.shape, max_depth,  # type: ignore[union-attr]
                         trunc_voxels)
    for kf in kfs:
        depth, rgb = undistort_small(kf, K_small, dist)
        # colour as float32 (h,w,3): OpenCV 5's coloured TSDF refuses uint8; the channel order is kept as given
        volume.integrateColor(_integrable_depth(depth, max_depth, edge_rel), rgb.astype(np.float32),
                              kf.T_WC.astype(np.float32))
    return _surface_points(volume)


def _no_points() -> tuple[np.ndarray, np.ndarray]:
    """No surface: points (0,3) float32 and colours (0,3) uint8."""
    return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)


def _keyframes_box(kfs: list[KeyFrame], K: np.ndarray, stride: int, voxel: float, max_depth: float,
                   dist: np.ndarray | None, edge_rel: float, margin: float) -> VolumeBox | None:
    """The volume's box around every 7th back-projected point of the keyframes (as the point map would fuse
    them), grown by `margin` metres; None when they have no point."""
    rays = pixel_rays(K, dist, kfs[0].depth_small.shape, stride)  # type: ignore[union-attr]
    sample = np.vstack([backproject_keyframe(kf, K, stride, max_depth, rays, edge_rel)[0][::7] for kf in kfs])
    if len(sample) == 0:
        return None
    return volume_box(sample, voxel, margin=margin)


def _new_volume(box: VolumeBox, K_small: np.ndarray, shape: tuple[int, int], max_depth: float,
                trunc_voxels: float) -> Any:
    """An empty coloured TSDF volume (OpenCV's `cv2.Volume`) over `box`, integrating and raycasting images of
    `shape` (h, w) with intrinsics `K_small` 3x3 and float depth in metres up to `max_depth`."""
    import cv2

    h, w = shape
    settings = cv2.VolumeSettings(cv2.VolumeType_ColorTSDF)
    for setter in (settings.setCameraIntegrateIntrinsics, settings.setCameraRaycastIntrinsics):
        setter(K_small)
    settings.setIntegrateWidth(w)
    settings.setIntegrateHeight(h)
    settings.setRaycastWidth(w)
    settings.setRaycastHeight(h)
    settings.setVoxelSize(box.voxel)
    settings.setTsdfTruncateDistance(trunc_voxels * box.voxel)
    settings.setDepthFactor(1.0)  # depth is float metres
    settings.setMaxDepth(max_depth)
    settings.setVolumeResolution(np.array(box.shape, np.int32))
    pose = np.eye(4, dtype=np.float32)
    pose[:3, 3] = box.origin
    settings.setVolumePose(pose)
    return cv2.Volume(cv2.VolumeType_ColorTSDF, settings)


def _integrable_depth(depth: np.ndarray, max_depth: float, edge_rel: float) -> np.ndarray:
    """A copy of strided `depth` (h,w) m as float32, 0 (not integrated) beyond `max_depth`, in the outer
    `BORDER_PX` frame and at depth edges (`edge_rel`; 0 = none)."""
    depth = np.where((depth > 0) & (depth < max_depth), depth, 0).astype(np.float32)
    depth[:BORDER_PX] = depth[-BORDER_PX:] = 0  # the colour lookup of the outermost pixels falls off the
    depth[:, :BORDER_PX] = depth[:, -BORDER_PX:] = 0  # image in OpenCV (black voxels): integrate inside only
    if edge_rel > 0:
        depth[depth_edges(depth, edge_rel)] = 0
    return depth


def _surface_points(volume: Any) -> tuple[np.ndarray, np.ndarray]:
    """The volume's coloured surface points: (M,3) float32 world points and (M,3) uint8 RGB, in a fixed order."""
    points, _normals, colours = volume.fetchPointsNormalsColors()
    if points is None or len(points) == 0:
        return _no_points()
    xyz = np.asarray(points, np.float32).reshape(-1, np.asarray(points).shape[-1])[:, :3]
    rgb_out = np.asarray(colours, np.float32).reshape(-1, np.asarray(colours).shape[-1])[:, :3]
    # a surface voxel no colour sample reached (silhouette rims) comes back black (< 1 of 255); a blended real
    # colour is never that dark in all three channels, so those are dropped rather than drawn as black specks
    coloured = rgb_out.max(axis=1) >= 1.0
    xyz, rgb_out = xyz[coloured], rgb_out[coloured]
    # the volume is fetched in parallel, so its point order varies run to run: sort (x, then y, then z) so that
    # the same keyframes always write the same map.ply
    order = np.lexsort((xyz[:, 2], xyz[:, 1], xyz[:, 0]))
    return (np.ascontiguousarray(xyz[order]),
            np.clip(rgb_out[order] + 0.5, 0, 255).astype(np.uint8))
