"""What tracking one frame produced."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.features.types import Features
from worker.slam.map.keyframe import KeyFrame


@dataclass
class TrackResult:
    """`T_WC` 4x4 float64 (the motion-model prediction when `ok` is False). `point_ids` (N,) int64: map point
    matched to each keypoint of `feats` (-1 none, outliers removed). `covariance` (6,6) of the T_CW left
    perturbation (rho, phi) from motion-only BA (see `pose_optimizer.PoseEstimate`), None when lost."""

    index: int
    timestamp: float
    T_WC: np.ndarray
    ok: bool
    relocalised: bool
    feats: Features
    point_ids: np.ndarray
    covariance: np.ndarray | None
    ref_kf: int
    keyframe: KeyFrame | None = None
    new_map: bool = False
    """This (lost) frame started a new map as its first keyframe (see `recovery.LossAction`)."""
    merged: bool = False
    """This keyframe relocalised in an older map, and its map (started after a loss) was moved onto it."""

    @property
    def n_tracked(self) -> int:
        return int((self.point_ids >= 0).sum())
