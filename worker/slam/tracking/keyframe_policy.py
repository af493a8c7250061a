"""When to insert a keyframe (ORB-SLAM2's RGB-D rules, with mapping run synchronously)."""
from __future__ import annotations

from dataclasses import dataclass

from worker.slam.config import TrackingConfig


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


def need_keyframe(s: KeyframeDecisionInput, cfg: TrackingConfig) -> bool:
    if s.frames_since_kf < cfg.keyframe_min_frames:
        return False
    need_close = s.close_tracked < cfg.keyframe_min_close and s.close_untracked > 70
    timeout = s.frames_since_kf >= cfg.keyframe_max_frames
    weak = s.tracked < cfg.keyframe_ratio * s.ref_tracked or need_close
    return (timeout or weak) and s.tracked > 15
