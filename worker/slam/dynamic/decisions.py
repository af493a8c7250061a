"""Which segments move, given their matches' scores: each segment's Δd, its verdict, the pixels it makes
dynamic (grown along its surface, kept where it locally agrees with the static scene), moving clusters no
segment covers, and the exclusion band around them."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from worker.slam.dynamic.culling_config import CullingConfig
from worker.slam.dynamic.matching import MatchedPoints
from worker.slam.dynamic.object_motion import estimate_object_motion
from worker.slam.dynamic.pair import FramePair
from worker.slam.dynamic.scoring import SegmentScores
from worker.slam.dynamic.segments import grow_by_depth, pixels_of
from worker.slam.dynamic.sorted_stats import median_of_sorted, quantile_of_sorted
from worker.slam.dynamic.threshold import object_threshold
from worker.slam.features.depth import backproject
from worker.slam.features.grid import PointGrid


@dataclass(frozen=True)
class SegmentDecision:
    label: int
    kind: str  # "semantic" or "geometric"
    points: int
    score: float
    dynamic: bool
    threshold_px: float = 0.0
    """The Δd it was judged against."""
    object_level: bool = False
    """True when Δd came from the segment's own motion estimate (`threshold.mode: object`), False when from
    the frame's (frame mode, or too few points with depth on the segment)."""


@dataclass(frozen=True)
class Segments:
    """The current frame's potentially dynamic segments: `labels` (H, W) int32, 1..`n_labels` (0 = none), and
    `point_label` (N,) int, the segment of each match's current point."""

    labels: np.ndarray
    point_label: np.ndarray
    n_labels: int


@dataclass(frozen=True)
class Verdicts:
    """Per segment label (index 0 = no segment): `moving` (L+1,) bool, `thr` (L+1,) float Δd px."""

    moving: np.ndarray
    thr: np.ndarray


def judge_segments(pair: FramePair, pts: MatchedPoints, seg: Segments, scores: np.ndarray, thr: float,
                   judged: bool, config: CullingConfig) -> tuple[list[SegmentDecision], Verdicts]:
    """Each segment moving or not: the `segment_quantile` of its matches' `scores` (N,) above its Δd (`thr`,
    the frame's, or the segment's own in `threshold.mode: object`); undecided segments (too few points, or the
    frame not `judged`) follow `undecided_dynamic`."""
    decisions = []
    n_labels = seg.n_labels
    moving_label = np.zeros(n_labels + 1, bool)
    thr_label = np.full(n_labels + 1, thr)
    object_level = config.threshold.mode == "object" and pair.prev_depth is not None and pair.K is not None
    z_prev = pair.prev_depth_at(pts.prev) if object_level and pair.prev_depth is not None else None
    by_segment = SegmentScores.of(scores, seg.point_label, n_labels)
    for lab in range(1, n_labels + 1):
        s = by_segment.of_segment(lab)
        by_object = False
        if z_prev is not None and pair.K is not None:
            own = _object_threshold(pair, pair.K, pts, z_prev, seg.point_label == lab, config)
            if own is not None:
                thr_label[lab] = own
                by_object = True
        if len(s) < config.min_points or not judged:
            moving = config.undecided_dynamic
        else:
            moving = quantile_of_sorted(s, config.segment_quantile) > thr_label[lab]
        decisions.append(SegmentDecision(lab, "semantic", len(s), median_of_sorted(s) if len(s) else 0.0, moving,
                                         float(thr_label[lab]), by_object))
        moving_label[lab] = moving
    return decisions, Verdicts(moving_label, thr_label)


def _object_threshold(pair: FramePair, K: np.ndarray, pts: MatchedPoints, z_prev: np.ndarray, on: np.ndarray,
                      config: CullingConfig) -> float | None:
    """Δd px of one segment from its own motion estimate on its matches `on` (N,) bool with previous depth
    `z_prev` (N,) m; None when that estimate fails."""
    sel = on & (z_prev > 0)
    motion = estimate_object_motion(backproject(pts.prev[sel], z_prev[sel], K), pts.cur[sel], K, pair.T_cur_prev,
                                    config.object_motion)
    if motion is None:
        return None
    return object_threshold(motion.cov, config.threshold)[0]


def grow_segments(seg: Segments, verdicts: Verdicts, depth: np.ndarray, pts: MatchedPoints,
                  config: CullingConfig) -> Segments:
    """`seg` with each moving segment extended along its surface in `depth` (H, W) m (see `grow_px`): the grown
    pixels join their segment, so the local decisions judge them with its points."""
    if not (config.grow_px > 0 and verdicts.moving.any()):
        return seg
    labels = seg.labels.copy()
    for grow_lab in np.flatnonzero(verdicts.moving):
        grown = grow_by_depth(labels == grow_lab, depth, config.grow_px, config.grow_rel_depth, config.depth_jump)
        labels[grown & (labels == 0)] = grow_lab
    return Segments(labels, pts.labels_at(labels), seg.n_labels)


def dynamic_pixels(seg: Segments, verdicts: Verdicts, pts: MatchedPoints, scores: np.ndarray, judged: bool,
                   config: CullingConfig) -> np.ndarray:
    """bool (H, W): the pixels of the moving segments, less the static-looking parts of large ones."""
    h, w = seg.labels.shape
    # one pass over the image for all segments (none when nothing moves)
    dynamic = pixels_of(seg.labels, verdicts.moving) if verdicts.moving.any() else np.zeros((h, w), bool)
    if config.local_px > 0 and seg.n_labels and judged:
        dynamic = _local_decisions(seg, verdicts, dynamic, pts, scores, config)
    return dynamic


def _local_decisions(seg: Segments, verdicts: Verdicts, dynamic: np.ndarray, pts: MatchedPoints,
                     scores: np.ndarray, config: CullingConfig) -> np.ndarray:
    """`dynamic` (H, W) with the static-looking parts of large dynamic segments kept (see `local_px`);
    `verdicts.thr` (L+1,) is each segment's Δd."""
    labels, moving_label, point_label, thr_label = seg.labels, verdicts.moving, seg.point_label, verdicts.thr
    h, w = labels.shape
    s = config.local_step_px
    gy, gx = np.mgrid[s // 2:h:s, s // 2:w:s]  # a coarse pixel grid, decided then spread to its cells
    grid_labels = labels[gy, gx]
    # a segment's area from the grid (one sample per s x s cell): no pass over the full image per frame
    area = np.bincount(grid_labels.ravel(), minlength=len(moving_label)) * s * s
    large = np.flatnonzero((area >= config.local_min_area * h * w) & moving_label)
    large = large[large > 0]
    if not len(large):
        return dynamic
    out = dynamic.copy()
    for lab in large:
        on = point_label == lab
        if on.sum() < config.local_k:
            continue
        cell = grid_labels == lab
        q = np.stack([gx[cell], gy[cell]], 1)
        # cells as wide as the radius: a query scans 3x3 of them (a segment's few dozen points are sparse)
        idx = PointGrid.of(np.stack([pts.xi[on], pts.yi[on]], 1), config.local_px).nearest(q, config.local_px,
                                                                                          config.local_k)
        near = idx[:, -1] >= 0  # all k within local_px
        # only towards "static": a few bad matches among a moving object's points must not keep it, but k
        # nearby points that all agree with the static scene are not on it (one-way: a small moving part of a
        # segment judged static is not looked for; k points are a weaker test than the whole segment's)
        keep = np.zeros(len(q), bool)
        keep[near] = np.median(scores[on][idx[near]], axis=1) <= thr_label[lab]
        if not keep.any():
            continue
        flag = np.zeros(cell.shape, bool)
        flag[cell] = keep
        # spread the kept cells to their s x s pixels, within the cells' bounding box only
        rows, cols = np.flatnonzero(flag.any(1)), np.flatnonzero(flag.any(0))
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        block = np.repeat(np.repeat(flag[r0:r1, c0:c1], s, 0), s, 1)
        y0, x0 = r0 * s, c0 * s
        y1, x1 = min(r1 * s, h), min(c1 * s, w)
        window = out[y0:y1, x0:x1]
        window[(labels[y0:y1, x0:x1] == lab) & block[:y1 - y0, :x1 - x0]] = False
    return out


def geometric_regions(pts: MatchedPoints, scores: np.ndarray, thr: float, depth: np.ndarray, covered: np.ndarray,
                      config: CullingConfig) -> tuple[list[SegmentDecision], np.ndarray]:
    """Moving clusters outside the segments (`covered` (N,) bool: the match is on one): a decision each, and
    the union of their regions, bool (H, W) like `depth`."""
    decisions = []
    clusters = np.zeros(depth.shape, bool)
    for k, region in enumerate(_geometric_clusters(pts.cur, scores > thr, depth, covered, config)):
        inside = region[pts.yi, pts.xi]
        decisions.append(SegmentDecision(-(k + 1), "geometric", int(inside.sum()),
                                         float(np.median(scores[inside])) if inside.any() else 0.0, True, thr))
        clusters |= region
    return decisions, clusters


def _geometric_clusters(p_cur: np.ndarray, moving: np.ndarray, depth: np.ndarray, covered: np.ndarray,
                        config: CullingConfig) -> list[np.ndarray]:
    """Regions (bool masks) around clusters of moving points with consistent depth, outside `covered`."""
    h, w = depth.shape
    c = config.cluster_cell
    gh, gw = (h + c - 1) // c, (w + c - 1) // c
    cell = (np.clip(p_cur[:, 1] // c, 0, gh - 1).astype(int), np.clip(p_cur[:, 0] // c, 0, gw - 1).astype(int))
    grid = np.zeros((gh, gw), np.uint8)
    sel = moving & ~covered
    grid[cell[0][sel], cell[1][sel]] = 1
    n, lab = cv2.connectedComponents(cv2.dilate(grid, np.ones((3, 3), np.uint8)), connectivity=8)
    regions = []
    point_lab = lab[cell]
    for k in range(1, n):
        in_k = point_lab == k
        mov_k = in_k & sel
        if mov_k.sum() < config.cluster_min_points or mov_k.sum() < 0.5 * in_k.sum():
            continue  # a few outliers among many static points: noise, not an object
        xi = np.clip(np.round(p_cur[mov_k, 0]).astype(int), 0, w - 1)
        yi = np.clip(np.round(p_cur[mov_k, 1]).astype(int), 0, h - 1)
        zs = depth[yi, xi]
        zs = zs[zs > 0]
        ys, xs = np.nonzero(cv2.resize((lab == k).astype(np.uint8), (gw * c, gh * c),
                                       interpolation=cv2.INTER_NEAREST)[:h, :w])
        region = np.zeros((h, w), bool)
        region[ys, xs] = True
        if len(zs):
            zmed = float(np.median(zs))
            region &= np.abs(depth - zmed) < config.cluster_depth_tol * zmed
        regions.append(region)
    return regions


def dilate_disc(mask: np.ndarray, px: int) -> np.ndarray:
    """`mask` (H, W) bool grown by a disc of radius `px`, computed only around its bounding box."""
    out = np.zeros_like(mask, dtype=bool)
    x, y, w, h = cv2.boundingRect(mask.astype(np.uint8))
    if w == 0 or px <= 0:
        return mask.copy()
    H, W = mask.shape
    y0, y1, x0, x1 = max(y - px, 0), min(y + h + px, H), max(x - px, 0), min(x + w + px, W)
    k = 2 * px + 1
    out[y0:y1, x0:x1] = cv2.dilate(mask[y0:y1, x0:x1].astype(np.uint8),
                                   cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
    return out
