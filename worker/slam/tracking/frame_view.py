"""One frame as the tracker sees it: its keypoints (given by the stages or extracted here) and its images."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from worker.slam.config import FeatureConfig
from worker.slam.features.depth import depth_weights, lookup_depth
from worker.slam.features.orb import OrbExtractor
from worker.slam.features.types import Features
from worker.slam.sensor import SensorModel
from worker.slam.tracking.inputs import TrackInputs


@dataclass(frozen=True)
class FrameView:
    """The frame's keypoints and the images a keyframe made of it keeps; images are the frame's (H,W)."""

    feats: Features
    """Undistorted keypoints (ideal pinhole pixels; `uv_raw` the raw ones) with their depth in metres."""
    rgb: np.ndarray
    """uint8 RGB (H,W,3): the restored colour when the stages gave one, else the raw colour."""
    dense_depth: np.ndarray
    """float32 metres (H,W): what the dense map fuses (restored depth, or the raw depth minus the exclude mask)."""
    measured: np.ndarray
    """float32 metres (H,W): the raw depth as measured."""


def frame_view(rgb: np.ndarray, depth: np.ndarray, given: TrackInputs, extractor: OrbExtractor,
               fc: FeatureConfig, sensor: SensorModel) -> FrameView:
    """The frame `rgb` (H,W,3) uint8, `depth` (H,W) float32 metres with what the stages found (`given`): their
    keypoints (depth refreshed from the restored depth) or keypoints extracted here outside the exclude mask,
    plus the extra keypoints, undistorted."""
    exclude_mask, restored_depth = given.exclude_mask, given.restored_depth
    if given.restored_rgb is not None:
        rgb = given.restored_rgb
    used_depth = restored_depth if restored_depth is not None else depth
    if given.features is not None:
        feats = given.features
        if restored_depth is not None and len(feats):
            feats = feats.select(np.arange(len(feats)))
            feats.depth = lookup_depth(feats.uv, used_depth, fc.min_depth_m, fc.max_depth_m,
                                       edge_radius=fc.depth_edge_radius_px)
    else:
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        feats = extractor.extract(gray, used_depth, exclude_mask)
    extra_features = given.extra_features
    if extra_features is not None and len(extra_features):
        extra = extra_features.select(np.arange(len(extra_features)))
        missing = extra.depth <= 0
        extra.depth[missing] = lookup_depth(extra.uv[missing], used_depth, fc.min_depth_m, fc.max_depth_m)
        feats = Features.concat([feats, extra])
    if sensor.depth_sigma_k > 0 and len(feats):
        dw = depth_weights(feats.uv, feats.depth, used_depth, sensor.bf, sensor.depth_sigma_k)
        feats = dataclasses.replace(feats, depth_w=dw)
    dense_depth = used_depth
    if exclude_mask is not None and restored_depth is None:
        dense_depth = np.where(exclude_mask, 0.0, depth).astype(np.float32)
    return FrameView(undistorted(feats, sensor), rgb, dense_depth, depth)


def undistorted(feats: Features, sensor: SensorModel) -> Features:
    """Keypoints to ideal pinhole pixels (ORB-SLAM2 undistorts keypoints, not images); as they are when the
    camera has no distortion."""
    if sensor.dist is None or not len(feats):
        return feats
    und = cv2.undistortPoints(feats.uv.reshape(-1, 1, 2), sensor.K, sensor.dist, P=sensor.K)
    return Features(und.reshape(-1, 2).astype(np.float64), feats.octave, feats.response, feats.desc,
                    feats.depth, uv_raw=feats.uv, depth_w=feats.depth_w)
