"""Every frame's pose re-solved against the final map, once the run's last bundle adjustment is done.

A frame is tracked against the map as it was at that moment; afterwards local and global BA move the points it
matched. Its stored pose (reference keyframe x relative pose) follows the keyframe but keeps the old points'
error. Once every frame has been tracked and the final global BA is done, each tracked non-keyframe frame is
solved once more by the tracker's motion-only BA against the final positions of the points it matched (its
inliers at tracking time), starting from its stored pose. Keyframes keep their bundle-adjusted poses.
Corrections seen: median 2-4 mm, at most 3 cm and 1 degree (augmented seed 5, synthetic room seed 1).
Every solve (keyframes' too, at their kept pose) also yields its pose information, which the smoother that
follows (`mapping/smoothing.py`) weighs each frame by.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from worker.slam.config import TrackingConfig
from worker.slam.geometry.pose_optimizer import optimize_pose
from worker.slam.map.map_points import MapPoints
from worker.slam.mapping.smoothing import world_information
from worker.slam.sensor import SensorModel


@dataclass
class FrameMatches:
    """What one tracked frame matched: map point `ids` (M,) int32, undistorted pixels `uv` (M,2) float32,
    keypoint depth `depth` (M,) float32 metres (0 = none), pyramid `octave` (M,) int8; `keyframe`: its pose
    is bundle adjusted (kept; solved only for its information)."""

    ids: np.ndarray
    uv: np.ndarray
    depth: np.ndarray
    octave: np.ndarray
    keyframe: bool = False
    depth_w: np.ndarray | None = None
    """(M,) float16 scale of each depth residual (`features.depth.depth_weights`); None = all 1."""


@dataclass
class FrameMatchLog:
    """Per frame of a run, its matches (None: lost); ~6 kB per frame (7-Scenes, 300 frames: mean 5.8 kB, at
    most 14.5)."""

    frames: list[FrameMatches | None] = field(default_factory=list)

    def add(self, point_ids: np.ndarray, uv: np.ndarray, depth: np.ndarray, octave: np.ndarray,
            keep: bool, keyframe: bool = False, depth_w: np.ndarray | None = None) -> None:
        """`point_ids` (N,) int64 per keypoint (-1 = unmatched) with the keypoints' `uv` (N,2), `depth` (N,),
        `octave` (N,); `keep` False records the frame as not refittable (lost); `keyframe`: BA owns its pose."""
        if not keep:
            self.frames.append(None)
            return
        m = point_ids >= 0
        self.frames.append(FrameMatches(point_ids[m].astype(np.int32), uv[m].astype(np.float32),
                                        depth[m].astype(np.float32), octave[m].astype(np.int8), keyframe,
                                        None if depth_w is None else depth_w[m].astype(np.float16)))


def refit_poses(poses: np.ndarray, log: FrameMatchLog, points: MapPoints, sensor: SensorModel,
                tc: TrackingConfig) -> tuple[int, list[np.ndarray | None]]:
    """Re-solve in place each logged non-keyframe frame of `poses` (F,4,4) T_WC, world frame of the map, from its
    matches to the still-alive `points`, with the run's `sensor` and the tracker's motion-only BA settings `tc`;
    a frame keeps its pose when fewer than `tc.min_matches` alive points (or inliers of the new solve) remain.
    Returns the number re-solved and, per frame, the (6,6) information of its pose (`smoothing.world_information`
    coordinates, 1-pixel keypoints; None: no solve, or one that failed)."""
    n = 0
    info: list[np.ndarray | None] = [None] * len(poses)
    for k, m in enumerate(log.frames[:len(poses)]):
        if m is None:
            continue
        alive = points.alive[m.ids]
        if alive.sum() < tc.min_matches:
            continue
        ids = m.ids[alive]
        est = optimize_pose(poses[k], points.pos[ids], m.uv[alive].astype(np.float64),
                            m.depth[alive].astype(np.float64), sensor.inv_sigma2[m.octave[alive]], sensor.K,
                            sensor.bf, tc.huber_px, tc.ba_rounds, tc.ba_iterations,
                            depth_w=None if m.depth_w is None else m.depth_w[alive].astype(np.float64))
        if est.n_inliers < tc.min_matches:
            continue
        if not m.keyframe:
            poses[k] = est.T_WC
            n += 1
        if est.covariance is not None and np.all(np.isfinite(est.covariance)):
            info[k] = world_information(poses[k], np.linalg.inv(est.covariance))
    return n, info
