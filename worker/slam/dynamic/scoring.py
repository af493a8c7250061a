"""How much each match moves against the static scene (its motion score), and each segment's scores.

A match's score is its distance to the epipolar line of F (fitted to the static matches); with the previous
frame's depth, at least its reprojection error under the depth test's pose; with a confirmed prediction, at
most its reprojection error under that prediction (the prediction veto).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from worker.slam.dynamic.culling_config import CullingConfig
from worker.slam.dynamic.epipolar import (
    epipolar_distance,
    fundamental_from_seed,
    fundamental_of_pose,
    fundamental_ransac,
    predict_positions,
)
from worker.slam.dynamic.matching import MatchedPoints
from worker.slam.dynamic.pair import FramePair
from worker.slam.dynamic.relative_pose import relative_pose, spread, veto_pose
from worker.slam.features.depth import backproject
from worker.slam.geometry.pnp import reprojection_px


@dataclass(frozen=True)
class _PrevDepth:
    """The matches' previous points with the previous frame's depth: `z` (N,) m (0 = none), `has` (N,) bool
    z > 0, `X` (N, 3) m in the previous camera (meaningful where `has`)."""

    z: np.ndarray
    has: np.ndarray
    X: np.ndarray


def score_matches(pair: FramePair, pts: MatchedPoints, static: np.ndarray, config: CullingConfig,
                  T_init: np.ndarray | None = None, segmented: bool = False,
                  pred_init: np.ndarray | None = None) -> np.ndarray | None:
    """Motion score (N,) in epipolar pixels of the matches `pts`; `static` (N,) bool: outside every segment.
    Inf-free, 0 where nothing could be measured. None when `segmented`, without a confirmed prediction
    (`T_init`, 4x4 T_cur_prev), the depth test finds no pose (see `min_pose_support`).
    `pred_init` (N, 2) px: where `T_init` puts the matches' previous keypoints (guided matching computed it)."""
    p_prev, p_cur, K = pts.prev, pts.cur, pair.K
    d = None
    if config.use_depth and pair.prev_depth is not None and K is not None:
        z = pair.prev_depth_at(p_prev)
        d = _PrevDepth(z, z > 0, backproject(p_prev, z, K))
    pose = None
    if d is not None and K is not None:
        usable = spread(np.flatnonzero(d.has & static), config.fit_max_points)
        if len(usable) >= 6:
            pose = relative_pose(d.X[usable], p_cur[usable].astype(np.float64), K, T_init, config, segmented)
        if pose is None and segmented and T_init is None:
            return None
    F = fundamental(p_prev[static], p_cur[static], pose, K, config)
    predicted = config.prediction_veto and T_init is not None and pair.prev_depth is not None and K is not None
    if F is None and not predicted:
        return np.zeros(len(p_prev))
    # Without F (fewer than 8 matches outside the segments) a confirmed prediction alone scores the points.
    score = epipolar_distance(F, p_prev, p_cur) if F is not None else np.full(len(p_prev), np.inf)
    if d is not None and K is not None:
        has = d.has
        if pose is not None:
            err = reprojection_px(d.X[has], p_cur[has], K, *pose)
            score[has] = np.maximum(score[has], err / config.reprojection_scale)
        if config.prediction_veto and T_init is not None and has.any():
            # refined only where segments hold nearly all matches (see `refine_prediction_below`)
            refine = static.mean() < config.refine_prediction_below
            T_veto = veto_pose(d.X, p_cur, has, K, T_init, config) if refine else T_init
            pred = pred_init[has] if T_veto is T_init and pred_init is not None else \
                predict_positions(p_prev[has], d.z[has], T_veto, K)
            score[has] = np.fmin(score[has], np.linalg.norm(pred - p_cur[has], axis=1))  # NaN (behind) = no veto
    score[np.isinf(score)] = 0.0  # not measurable
    return score


def fundamental(p_prev: np.ndarray, p_cur: np.ndarray, pose: tuple[np.ndarray, np.ndarray] | None,
                K: np.ndarray | None, config: CullingConfig) -> np.ndarray | None:
    """F (3x3) of the static matches (N, 2) px: seeded by the depth test's pose (rvec, tvec) when there is one
    (see `seed_fundamental`), else by RANSAC; None with fewer than 8 matches."""
    if pose is not None and K is not None and config.seed_fundamental < 1.0:
        seed = fundamental_of_pose(cv2.Rodrigues(pose[0])[0], pose[1], K)
        F = fundamental_from_seed(p_prev, p_cur, seed, config.ransac_px, config.seed_fundamental)
        if F is not None:
            return F
    return fundamental_ransac(p_prev, p_cur, config.ransac_px, usac=config.usac)


@dataclass(frozen=True)
class SegmentScores:
    """Each segment's match scores, ascending: one sort for all segments instead of a mask and a quantile per
    segment. `sorted_scores` (N,) by (label, score); `starts` (L+2,): segment l's run begins at starts[l]."""

    sorted_scores: np.ndarray
    starts: np.ndarray

    @classmethod
    def of(cls, scores: np.ndarray, point_label: np.ndarray, n_labels: int) -> SegmentScores:
        """`scores` (N,) and `point_label` (N,) int in 0..n_labels (0 = outside every segment)."""
        order = np.lexsort((scores, point_label))
        sorted_scores = scores[order]
        starts = np.concatenate([[0], np.cumsum(np.bincount(point_label, minlength=n_labels + 1))])
        return cls(sorted_scores, starts)

    def of_segment(self, lab: int) -> np.ndarray:
        """Segment `lab`'s scores (M,), ascending."""
        return self.sorted_scores[self.starts[lab]:self.starts[lab + 1]]
