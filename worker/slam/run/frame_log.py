"""Per-frame records of a run, in frame order: what the trajectory, metrics.json and frame_stats are made of."""
from __future__ import annotations

from collections import defaultdict

import numpy as np

from worker.slam.geometry.se3 import inv
from worker.slam.map.map import Map
from worker.slam.mapping.frame_refit import FrameMatchLog
from worker.slam.tracking.result import TrackResult


def numbers(info: dict) -> dict[str, float]:
    """The numeric entries of a frame's `info` (flags left out), as floats."""
    return {k: float(v) for k, v in info.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


class FrameLog:
    """Every frame's timestamp, tracked flag, pose relative to its reference keyframe (so BA and loop corrections
    move it at the end), statistics row, and (`refit`) the map points it matched (`mapping/frame_refit.py`)."""

    def __init__(self, refit: bool) -> None:
        self.stamps: list[float] = []
        self.tracked: list[bool] = []
        self.rel: list[tuple[int, np.ndarray]] = []
        """Per frame: (reference keyframe id, T_ref_frame (4,4)); (0, T_WC) while the map is empty."""
        self.rows: list[dict] = []
        """Per frame: features, matched_points and the stages' numbers (frame_stats.csv)."""
        self.stage_info: dict[str, list[float]] = defaultdict(list)
        """The stages' per-frame numbers by name, for their means in metrics.json."""
        self.cpu_tracking: list[float] = []
        """CPU seconds (all threads) per frame's tracking: comparable when the machine is shared."""
        self.matches = FrameMatchLog() if refit else None
        self.relocalisations = self.new_maps = self.merges = 0
        self.most_features = self.most_with_depth = 0
        """The most features, and features with a valid depth, any frame had (why a run tracked nothing)."""

    def __len__(self) -> int:
        return len(self.stamps)

    def add_stage_info(self, info: dict) -> None:
        for key, val in numbers(info).items():
            self.stage_info[key].append(val)

    def add(self, timestamp: float, res: TrackResult, info: dict, slam_map: Map) -> dict:
        """Record a tracked frame (after its keyframe, if any, went through mapping) with its stages' `info`;
        returns its statistics row (deferred stage work may add to it later)."""
        self.stamps.append(timestamp)
        self.tracked.append(bool(res.ok))
        row = {"features": len(res.feats), "matched_points": int(np.sum(res.point_ids >= 0)),
               **{k: v for k, v in info.items() if isinstance(v, (int, float))}}
        self.rows.append(row)
        self.relocalisations += int(res.relocalised)
        self.new_maps += int(res.new_map)
        self.merges += int(res.merged)
        self.most_features = max(self.most_features, len(res.feats))
        self.most_with_depth = max(self.most_with_depth, int(np.count_nonzero(res.feats.depth > 0)))
        self.rel.append(_relative(slam_map, res))
        if self.matches is not None:
            self.matches.add(res.point_ids, res.feats.uv, res.feats.depth, res.feats.octave, bool(res.ok),
                             keyframe=res.keyframe is not None, depth_w=res.feats.depth_w)
        return row

    def poses(self, slam_map: Map) -> np.ndarray:
        """(N,4,4) T_WC of every frame, through its reference keyframe's current pose."""
        return np.stack([slam_map.keyframes[r].T_WC @ T_rf if len(slam_map) else T_rf for r, T_rf in self.rel])

    def finished_rows(self, start: int, ate_errors: dict[float, float] | None) -> list[dict]:
        """The rows completed with frame_index (`start` + position), timestamp, tracked and ate_error (m)."""
        for k, row in enumerate(self.rows):
            row.update(frame_index=start + k, timestamp=float(self.stamps[k]), tracked=bool(self.tracked[k]),
                       ate_error=None if ate_errors is None else ate_errors.get(round(float(self.stamps[k]), 6)))
        return self.rows


def _relative(slam_map: Map, res: TrackResult) -> tuple[int, np.ndarray]:
    if not len(slam_map):
        return 0, res.T_WC.copy()
    ref = min(res.ref_kf, len(slam_map) - 1)
    return ref, inv(slam_map.keyframes[ref].T_WC) @ res.T_WC
