"""Decide which objects move between the previous and the current frame, and which pixels to exclude.

Per match, the motion score is its distance to the epipolar line of a fundamental matrix fitted to the matches
outside potentially dynamic segments; where the previous frame has depth, also its reprojection error under
the relative pose from PnP (this catches motion *along* the epipolar line, which F cannot see); with the
tracker's predicted pose, at most its reprojection error under that prediction (see `prediction_veto`). An object is
dynamic when the median score of its points exceeds the adaptive threshold Δd = f(H); all its pixels (dilated)
are then excluded. A still object of a dynamic class (a sitting person) keeps its features. Without segmentation
(or for objects no class covers) clusters of high-score points with consistent depth become dynamic regions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.dynamic.culling_config import CullingConfig
from worker.slam.dynamic.decisions import (
    SegmentDecision,
    Segments,
    dilate_disc,
    dynamic_pixels,
    geometric_regions,
    grow_segments,
    judge_segments,
)
from worker.slam.dynamic.matching import MatchedPoints, match_frames
from worker.slam.dynamic.pair import FramePair, nearest_pixel
from worker.slam.dynamic.scoring import score_matches
from worker.slam.dynamic.segments import split_segments
from worker.slam.dynamic.threshold import adaptive_threshold, motion_entropy

__all__ = ["CullingConfig", "CullingResult", "FramePair", "SegmentDecision", "cull_frame", "cull_pair",
           "dilate_disc", "mask_at"]


@dataclass(frozen=True)
class CullingResult:
    """`dynamic_mask` / `exclude_mask` bool (H, W); per-match `scores` (N,) and `cur_points` (N, 2) px."""

    dynamic_mask: np.ndarray
    exclude_mask: np.ndarray
    segments: list[SegmentDecision]
    threshold_px: float
    entropy: float | None
    matches: int
    scores: np.ndarray
    cur_points: np.ndarray
    guided: bool = False
    """True when the matches came from the pose-guided search (False: brute force)."""
    judged: bool = True
    """False when the frame could not be judged and its segments were taken as undecided (`min_pose_support`)."""
    without_objects: bool = False
    """True when segmentation left no segment to judge (and `detect_unknown` is off): nothing was matched or
    scored, since no decision would use it (45 of Bonn's 313 frames with MSNET; most of static 7-Scenes)."""
    marks_trusted: bool = False
    """True when the marks covered no more than `judge_marks_above` of the view: every marked segment was
    excluded without a motion test, and nothing was matched or scored."""

    def removed(self, keypoints_xy: np.ndarray) -> np.ndarray:
        """bool (M,): which of the current frame's keypoints (M, 2) fall in the excluded region."""
        return mask_at(self.exclude_mask, keypoints_xy)


def mask_at(mask: np.ndarray, keypoints_xy: np.ndarray) -> np.ndarray:
    """bool (M,): `mask` (H, W) at the nearest pixel of each keypoint (M, 2) (x, y), clipped to the image."""
    h, w = mask.shape
    return mask[nearest_pixel(keypoints_xy[:, 1], h), nearest_pixel(keypoints_xy[:, 0], w)] if len(keypoints_xy) \
        else np.zeros(0, bool)


def cull_frame(kp_prev: np.ndarray, desc_prev: np.ndarray, kp_cur: np.ndarray, desc_cur: np.ndarray,
               depth_cur: np.ndarray, potentially_dynamic: np.ndarray | None, pose_cov: np.ndarray | None,
               config: CullingConfig = CullingConfig(), prev_depth: np.ndarray | None = None,
               K: np.ndarray | None = None, T_cur_prev: np.ndarray | None = None) -> CullingResult:
    """Judge the objects of the current frame (`cull_pair` of the `FramePair` of these arrays).

    `kp_*` (N, 2) pixel coordinates (x, y) with ORB `desc_*` (N, 32) uint8; `depth_cur` float32 m (H, W);
    `potentially_dynamic` bool (H, W) from segmentation (None in geometry-only mode); `pose_cov` the 6x6
    covariance of the previous pose estimate (for Δd); `prev_depth` + `K` enable the reprojection test;
    `T_cur_prev` (4x4, X_cur = T X_prev), the predicted relative pose, enables guided matching. With
    segmentation that leaves no segment, nothing is matched (`CullingResult.without_objects`).
    """
    return cull_pair(FramePair(kp_prev, desc_prev, kp_cur, desc_cur, depth_cur, potentially_dynamic, pose_cov,
                               prev_depth, K, T_cur_prev), config)


def cull_pair(pair: FramePair, config: CullingConfig = CullingConfig()) -> CullingResult:
    """Judge the objects of `pair`'s current frame: split the marks into segments, match, score the matches,
    decide per segment (and per moving cluster outside them), exclude the dynamic pixels with a band."""
    h, w = pair.shape
    entropy = motion_entropy(pair.pose_cov)
    thr = adaptive_threshold(entropy, config.threshold)
    marked = pair.potentially_dynamic
    use_sem = config.use_segmentation and marked is not None
    labels = split_segments(marked, pair.cur_depth, config.min_segment_area, config.depth_jump, config.segment_step) \
        if use_sem and marked is not None else np.zeros((h, w), np.int32)
    if use_sem and not config.detect_unknown and not labels.any():
        empty = np.zeros((h, w), bool)
        return CullingResult(empty, empty, [], thr, entropy, 0, np.zeros(0), np.zeros((0, 2)), without_objects=True)
    if config.judge_marks_above > 0 and use_sem and marked is not None and not config.detect_unknown \
            and marked.mean() <= config.judge_marks_above:  # off (0): no pass over the mask
        return _trusted_marks(labels, thr, entropy, config)
    # Keypoints on objects are matched exhaustively (a search radius would keep only their small motions and
    # bias the decision towards "static"); the static rest, when a pose is predicted, by the guided search.
    on_object = labels[nearest_pixel(pair.cur_uv[:, 1], h), nearest_pixel(pair.cur_uv[:, 0], w)] > 0 \
        if use_sem else None
    m = match_frames(pair, on_object, config)
    pts = MatchedPoints.of(pair, m)
    seg = Segments(labels, pts.labels_at(labels), int(labels.max()))
    # Refining the predicted pose needs a clean static set; without segments moving points are in it, and a
    # wide first gate would let them pull the pose along (RANSAC instead).
    T_init = pair.T_cur_prev if m.guided and use_sem else None
    pred = m.pred[m.prev_idx] if m.pred is not None and T_init is not None else None
    scores = score_matches(pair, pts, seg.point_label == 0, config, T_init, use_sem, pred) \
        if len(pts) >= 8 else np.zeros(len(pts))
    judged = scores is not None  # False: no segment can be judged (see `min_pose_support`)
    if scores is None:
        scores = np.zeros(len(pts))
    decisions, verdicts = judge_segments(pair, pts, seg, scores, thr, judged, config)
    seg = grow_segments(seg, verdicts, pair.cur_depth, pts, config)
    dynamic = dynamic_pixels(seg, verdicts, pts, scores, judged, config)
    exclude = dilate_disc(dynamic, config.dilation_px)
    if config.detect_unknown or not use_sem:
        found, clusters = geometric_regions(pts, scores, thr, pair.cur_depth, seg.point_label > 0, config)
        decisions += found
        dynamic |= clusters
        exclude |= dilate_disc(clusters, config.cluster_dilation_px)
    return CullingResult(dynamic, exclude, decisions, thr, entropy, len(pts), scores, pts.cur, m.guided, judged)


def _trusted_marks(labels: np.ndarray, thr: float, entropy: float | None, config: CullingConfig) -> CullingResult:
    """Every segment of `labels` (H, W) int32 dynamic, unjudged (see `judge_marks_above`)."""
    dynamic = labels > 0
    decisions = [SegmentDecision(lab, "semantic", 0, 0.0, True, thr) for lab in range(1, int(labels.max()) + 1)]
    return CullingResult(dynamic, dilate_disc(dynamic, config.dilation_px), decisions, thr, entropy, 0, np.zeros(0),
                         np.zeros((0, 2)), marks_trusted=True)
