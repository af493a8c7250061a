"""What the tracker does when a frame neither tracks nor relocalises (ORB-SLAM2's reset, Atlas-like new maps)."""
from __future__ import annotations

from enum import Enum

from worker.slam.config import TrackingConfig


class LossAction(Enum):
    WAIT = "wait"
    """Stay lost: the next frame tries tracking and relocalisation again."""
    NEW_MAP = "new_map"
    """Start a new map at the predicted pose; the old one stays for relocalisation and loop closure."""
    RESET = "reset"
    """The lost map was young: discard its points, then start a new map as above."""


def after_loss(lost_streak: int, map_keyframes: int, cfg: TrackingConfig) -> LossAction:
    """`lost_streak` consecutive lost frames (this one included); `map_keyframes` in the current map."""
    if lost_streak < cfg.new_map_after_lost:
        return LossAction.WAIT
    if map_keyframes <= cfg.reset_max_keyframes:
        return LossAction.RESET
    return LossAction.NEW_MAP


def can_start_map(n_new_points: int, cfg: TrackingConfig) -> bool:
    """A map's first keyframe must create enough points that tracking survives culling of some of them."""
    return n_new_points >= cfg.init_min_points
