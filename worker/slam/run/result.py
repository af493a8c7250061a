"""What a finished run produced."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from worker.slam.io.trajectory import Trajectory
from worker.slam.map.map import Map


@dataclass
class RunResult:
    trajectory: Trajectory
    """The tracked frames' T_WC (trajectory.txt): a frame never tracked has no pose; match by timestamp, or
    index it with `tracked`'s true entries, never by frame index."""
    keyframes: Trajectory
    metrics: dict
    """What metrics.json holds (`run.metrics.run_metrics`, then the stages' summaries and the evaluation)."""
    slam_map: Map
    tracked: np.ndarray
    """(N,) bool per frame."""
    cloud: tuple[np.ndarray, np.ndarray] | None = None
    """Dense map (M,3) float32 xyz, (M,3) uint8 RGB."""
    frame_stats: list[dict] = field(default_factory=list)
    """Per frame: frame_index, timestamp, tracked, features, matched_points, ate_error and stage numbers."""
    aligned_groundtruth: Trajectory | None = None
    """Ground truth expressed in the estimate's frame (SE(3)-aligned), for plots."""
    previews: dict[int, dict[str, np.ndarray]] = field(default_factory=dict)
    """A few frames' preview images by frame index."""
