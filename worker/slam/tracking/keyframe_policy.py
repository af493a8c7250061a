"""When to insert a keyframe (ORB-SLAM2's RGB-D rules, with mapping run synchronously)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.config import TrackingConfig
from worker.slam.map.map import Map


@dataclass
class KeyframeDecisionInput:
    frames_since_kf: int
    """Frames since the last keyframe was inserted."""
    tracked: int
    """Map points tracked (inliers) in the current frame."""
    ref_tracked: int
    """Map points observed by the reference keyframe."""
    close_tracked: int
    """Tracked points closer than `close_depth_m`."""
    close_untracked: int
    """Keypoints with close depth but no map point (new structure the map lacks)."""

    @classmethod
    def of_frame(cls, slam_map: Map, index: int, depth: np.ndarray, point_ids: np.ndarray, last_kf_frame: int,
                 close_depth_m: float) -> KeyframeDecisionInput:
        """Frame `index` with keypoint `depth` (N,) metres and matched `point_ids` (N,) (-1 none), against a
        non-empty `slam_map` whose last keyframe came from frame `last_kf_frame`."""
        # ORB-SLAM2 compares with the reference keyframe's well-established points (seen by >= 3 keyframes);
        # the newest keyframe stands in for it (it shares the most points with the current frame).
        ref = slam_map.keyframes[-1]
        ref_pids = ref.point_ids[ref.point_ids >= 0]
        min_obs = 3 if len(slam_map) > 2 else 2
        p = slam_map.points
        ref_tracked = int((p.alive[ref_pids] & (p.n_obs[ref_pids] >= min_obs)).sum())
        close = (depth > 0) & (depth < close_depth_m)
        tracked = point_ids >= 0
        return cls(index - last_kf_frame, int(tracked.sum()), ref_tracked, int((close & tracked).sum()),
                   int((close & ~tracked).sum()))


def need_keyframe(s: KeyframeDecisionInput, cfg: TrackingConfig) -> bool:
    if s.frames_since_kf < cfg.keyframe_min_frames:
        return False
    need_close = s.close_tracked < cfg.keyframe_min_close and s.close_untracked > 70
    timeout = s.frames_since_kf >= cfg.keyframe_max_frames
    weak = s.tracked < cfg.keyframe_ratio * s.ref_tracked or need_close
    return (timeout or weak) and s.tracked > 15
