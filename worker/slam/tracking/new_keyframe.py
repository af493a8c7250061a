"""A tracked frame made a keyframe: its new map points from keypoint depth, its strided images, into the map."""
from __future__ import annotations

import numpy as np

from worker.slam.features.depth import backproject
from worker.slam.geometry.se3 import transform
from worker.slam.map.keyframe import KeyFrame
from worker.slam.map.map import Map
from worker.slam.tracking.frame_view import FrameView
from worker.slam.tracking.result import TrackResult


def add_keyframe(slam_map: Map, res: TrackResult, view: FrameView, K: np.ndarray, scale_factor: float,
                 new_point_max_depth_m: float, image_stride: int) -> KeyFrame:
    """Add frame `res` (pose `res.T_WC`, keypoints `res.feats`) to `slam_map` as its next keyframe: tracked
    points gain an observation, untracked keypoints with depth below `new_point_max_depth_m` become map points
    (back-projected with `K`; `scale_factor` of the ORB pyramid), and the keyframe keeps `view`'s images
    subsampled by `image_stride`. `res.point_ids` becomes the keyframe's (the same array)."""
    feats, pids = res.feats, res.point_ids.copy()
    p = slam_map.points
    tracked = pids >= 0
    p.n_obs[pids[tracked]] += 1
    z = feats.depth
    new = ~tracked & (z > 0) & (z < new_point_max_depth_m)
    kf_id = len(slam_map)
    if new.any():
        X_c = backproject(feats.uv[new], z[new], K)
        pids[new] = p.add(transform(res.T_WC, X_c), feats.desc[new], res.T_WC[:3, 3], feats.octave[new],
                          scale_factor, kf_id)
    s = image_stride
    kf = KeyFrame(kf_id, res.index, res.timestamp, res.T_WC.copy(), feats, pids,
                  view.rgb[::s, ::s].copy(), np.ascontiguousarray(view.dense_depth[::s, ::s]).copy(),
                  np.ascontiguousarray(view.measured[::s, ::s]).copy())
    slam_map.add_keyframe(kf)
    res.point_ids = pids
    return kf
