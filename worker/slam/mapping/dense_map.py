"""The dense map `map.ply` is built from: the keyframes fused by the configured method."""
from __future__ import annotations

import numpy as np

from worker.slam.config import DenseConfig
from worker.slam.errors import ConfigError
from worker.slam.map.keyframe import KeyFrame
from worker.slam.mapping.carve import View, carve, keyframe_views
from worker.slam.mapping.dense import fuse_keyframes
from worker.slam.mapping.tsdf import fuse_tsdf


def build_dense_map(keyframes: list[KeyFrame], K: np.ndarray, dist: np.ndarray | None, cfg: DenseConfig,
                    carve_views: list[View] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World points (M,3) float32 and colours (M,3) uint8 RGB of the keyframes at their current `T_WC`.

    `K` 3x3 intrinsics of the full image, `dist` its OpenCV distortion (None = pinhole). `carve_views`: the
    frames whose measured depth votes in carving (`FrameViews`); None: the keyframes'."""
    if cfg.method == "points":
        xyz, rgb = fuse_keyframes(keyframes, K, cfg.stride, cfg.voxel_m, cfg.max_depth_m, dist, cfg.edge_rel)
    elif cfg.method == "tsdf":
        xyz, rgb = fuse_tsdf(keyframes, K, cfg.stride, cfg.voxel_m, cfg.max_depth_m, dist, cfg.edge_rel,
                             cfg.tsdf_trunc_voxels)
    else:
        raise ConfigError(f"dense.method must be 'points' or 'tsdf', not {cfg.method!r}")
    if not cfg.carve:
        return xyz, rgb
    views = keyframe_views(keyframes) if carve_views is None else carve_views
    return carve(xyz, rgb, views, K, cfg.stride, min_through=cfg.carve_min_through, majority=cfg.carve_majority)
