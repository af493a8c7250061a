"""What the per-frame stages hand the tracker for one frame (the tracker's side of the stage contract)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.features.types import Features


@dataclass(frozen=True)
class TrackInputs:
    """All optional; images have the frame's (H,W). Empty = the tracker extracts and uses the raw frame."""

    features: Features | None = None
    """The frame's keypoints already extracted (and culled) in raw image coordinates: used instead of
    extracting again (their depth is refreshed from `restored_depth` when there is one)."""
    exclude_mask: np.ndarray | None = None
    """bool (H,W): True pixels give no keypoints and are left out of the dense map."""
    extra_features: Features | None = None
    """Keypoints to add (e.g. found in restored regions); depth 0 is looked up."""
    restored_depth: np.ndarray | None = None
    """float32 metres (H,W): the frame's depth with dynamic regions filled; used for keypoint depth and the
    dense map instead of the raw depth."""
    restored_rgb: np.ndarray | None = None
    """uint8 RGB (H,W,3): the frame's colour with dynamic regions filled; replaces the raw colour."""
    held_back: Features | None = None
    """Keypoints culling removed (raw image coordinates, measured depth), offered only when the frame would be
    lost without them (`tracking.rescue_with_held_back`)."""
