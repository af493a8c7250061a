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

from dataclasses import dataclass, field

import cv2
import numpy as np

from worker.slam.config import valid
from worker.slam.dynamic.epipolar import (
    Matches,
    epipolar_distance,
    fundamental_from_seed,
    fundamental_of_pose,
    fundamental_ransac,
    match_guided,
    match_orb,
    predict_positions,
)
from worker.slam.dynamic.object_motion import ObjectMotionConfig, estimate_object_motion
from worker.slam.dynamic.segments import grow_by_depth, pixels_of, split_segments
from worker.slam.dynamic.sorted_stats import median_of_sorted, quantile_of_sorted
from worker.slam.dynamic.threshold import ThresholdConfig, adaptive_threshold, motion_entropy, object_threshold
from worker.slam.features.depth import backproject
from worker.slam.features.grid import PointGrid
from worker.slam.features.matching import hamming
from worker.slam.features.search import KeypointIndex
from worker.slam.geometry.pnp import reprojection_px, sqpnp_ransac


@dataclass(frozen=True)
class CullingConfig:
    """Dynamic culling of one frame against the previous one."""

    threshold: ThresholdConfig = field(default_factory=ThresholdConfig)
    object_motion: ObjectMotionConfig = field(default_factory=ObjectMotionConfig)
    """The per-segment motion estimate behind Δd in `threshold.mode: object`."""
    use_segmentation: bool = True
    """False = the `geometry-only` preset: no segments, only clusters of moving points."""
    detect_unknown: bool = False
    """With segmentation, also flag moving clusters no segment covers (the geometry-only path always does).
    Off by default: on synthetic truth the cluster path finds few moving points (features on walking people
    rarely match across frames) and removes static ones too."""
    ransac_px: float = valid(1.0, 0.01, 100.0)
    """RANSAC inlier threshold of the fundamental matrix (pixels)."""
    usac: bool = False
    """F's RANSAC and the depth test's PnP-RANSAC fallback by OpenCV's USAC instead of classic RANSAC: the
    slowest frames' culling 3x cheaper (Bonn mean 7.2 -> 5.3 ms), but worse `geometry-only` and Bonn ATE, so
    off (docs/results/realtime.md, 2026-12-04)."""
    seed_fundamental: float = valid(0.5, 0.0, 1.0)
    """When the depth test has its pose, F is fitted by least squares to the static matches that pose's own F
    explains within `ransac_px` (`epipolar.fundamental_from_seed`), if at least this fraction of them do;
    else, and without a pose, by RANSAC (1 = always RANSAC). The pose plays RANSAC's best hypothesis: 0.6 ms
    instead of 1.5 per Bonn frame on average, RANSAC included where the seed explains too little (8 % of the
    frames); the same ATE means over the development sequences (docs/results/realtime.md, "Culling at half the
    cost")."""
    fit_max_points: int = valid(200, 8, 100_000)
    """The depth test's pose is fitted on at most this many static matches (evenly picked): with mostly
    inliers more points make RANSAC slower, not the pose better; every match is then scored. (F keeps all
    static matches: on a nearly planar static scene a subset left it ill-determined in the tests.)"""
    match_max_distance: int = valid(50, 0, 256)
    """Hamming distance above which ORB matches are dropped."""
    guided_radius_px: float = valid(24.0, 0.5, 1000.0)
    """Search radius around a keypoint's predicted position when the relative pose is predicted (doubled for
    keypoints without depth). Wide enough for the prediction error and for people moving ~10 px per frame."""
    object_margin_px: float = valid(64.0, 0.0, 4096.0)
    """Previous keypoints are brute-force matched to the objects' keypoints when their predicted position
    falls within this margin of the objects' bounding box (the object's own motion over `lag_frames`)."""
    guided_min_matches: int = valid(40, 0, 100_000)
    """Fewer guided matches than this (a bad prediction) → brute-force cross-checked matching instead."""
    prefer_static_within: int = valid(20, 0, 256)
    """An object keypoint's brute-force match gives way to its guided match (a previous keypoint near where the
    prediction puts it if static) when that one's Hamming distance is at most this much larger (-1 = never):
    exhaustive matching picks the best descriptor anywhere near the objects, on repeated texture (kitchen
    cabinets) sometimes a wrong match far away. A modest gain on the means that touches few matches; guided
    matching of every object keypoint first instead lost tracking (docs/results/dynamic.md, "Ambiguous matches on
    objects")."""
    confirm_on_objects: bool = True
    """When too few keypoints outside the segments match the prediction, count the guided matches of all
    keypoints instead. Segmentation that marks most of the view (MSNET on the synthetic room) otherwise leaves
    the prediction unconfirmed, so the prediction veto is off exactly when F, fitted on the few points left
    outside, is least reliable (docs/results/dynamic.md, "The prediction under masks that cover the view")."""
    use_depth: bool = True
    """Add the reprojection test with the previous frame's depth."""
    pnp_px: float = valid(2.0, 0.01, 100.0)
    """RANSAC threshold of the depth test's PnP; wider lets a wrong motion explain a moving object too."""
    min_pose_support: float = valid(0.5, 0.0, 1.0)
    """The depth test's pose is used only when at least this fraction of the static points agree with it
    (within `pnp_px`): the predicted pose refined (no RANSAC) when it passes, else (with segments) PnP-RANSAC's
    pose when that passes. With segments and without a pose, a frame whose prediction guided matching did not
    confirm cannot be judged (see `undecided_dynamic`): its brute-force matches hold no motion most static
    points agree on (on Bonn: motion blur behind people who fill the view, where RANSAC's best pose had 0-30 %
    support, and every segment came out dynamic anyway), and fitting F to them cost 5-10 ms for scores nothing
    relied on. Without segments (`geometry-only`) the matches include every mover, so a pose's support says
    less, and any RANSAC pose is used as before."""
    ap3p_samples: bool = True
    """With segments, PnP-RANSAC's hypotheses by AP3P on 4 points, then SQPnP on the consensus
    (`pnp.sqpnp_ransac`): 3.6 ms instead of 11.5 for its 300 hypotheses on a Bonn frame. (`geometry-only`,
    which needs RANSAC on every frame, keeps SQPnP's samples: the change moved its development ATEs by up to 3x
    per sequence either way, docs/results/realtime.md "Culling without its tail".)"""
    reprojection_scale: float = valid(3.0, 0.01, 100.0)
    """A reprojection error counts as `error / scale` epipolar pixels (depth noise is larger than keypoint noise)."""
    prediction_veto: bool = True
    """With a predicted relative pose that guided matching confirmed, a point's score is at most its
    reprojection error under that prediction: it must move against the tracker's expectation too. F and the
    depth test's pose are fitted on the matches outside the segments, and when segmentation marks most of the
    static view and misses part of a person (MSNET: floor, chairs, red cabinets), that outside set is mostly
    the person; the whole static scene then looks moving and tracking is lost. Where segmentation is right the
    veto can only keep slow movers, so it trades a little there for not losing whole sequences (docs/results/dynamic.md,
    "Prediction veto")."""
    refine_prediction_below: float = valid(0.2, 0.0, 1.0)
    """When fewer than this fraction of the matches lie outside the segments, the prediction veto uses the
    predicted pose refined on all matched points (`_refine_from`: LM from the prediction on the points it
    explains, gates of 3 and 1 x `pnp_px`; a wide first gate let a mover pull the pose along) instead of the raw
    constant-velocity prediction (0 = never). There F and the depth pose, fitted on the few matches outside,
    are weak and the veto decides, and a prediction a few pixels off makes the whole static view look moving.
    Not always: an exact pose lets the veto keep slow movers (docs/results/dynamic.md, "The prediction under masks
    that cover the view")."""
    min_points: int = valid(3, 1, 100_000)
    """A segment needs this many matched points to be judged by geometry."""
    judge_marks_above: float = valid(0.0, 0.0, 1.0)
    """> 0: geometry judges the marked segments only in frames where segmentation marks more than this share of
    the view; below it every marked segment is excluded unjudged and nothing is matched
    (`CullingResult.marks_trusted`): a person who looks still over `lag_frames` is often starting or ending a
    walk. 0 (the default) = the paper: every mark is judged. 0.5 was measured (docs/results/dynamic.md, "Marks
    judged only where they cover most of the view"): development mean 0.0250 -> 0.0242 m and the true-mask
    oracle 0.0261 -> 0.0254, but the synthetic rooms 0.0076 -> 0.0078, so it stays an option. 1 = never judge:
    frames whose marks cover 90 % of the view then starve (40 of 60 tracked in the test of that name)."""
    undecided_dynamic: bool = True
    """A potentially dynamic segment with too few matched points to judge, or in a frame that cannot be judged
    (`min_pose_support`), is treated as dynamic (safe side: a person's features rarely match across frames when
    they walk)."""
    segment_quantile: float = valid(0.5, 0.0, 1.0)
    """A segment is dynamic when this quantile of its points' scores exceeds Δd (robust to a few bad matches)."""
    min_segment_area: int = valid(200, 0, 10_000_000)
    depth_jump: float = valid(0.05, 0.0, 10.0)
    """Relative depth jump that separates two segments."""
    segment_step: int = valid(2, 1, 8)
    """Segments are split on every `segment_step`-th row and column and their labels spread back to the mask's
    pixels (`segments.split_segments`): a quarter of the work at 2, the costliest part of culling where
    segmentation marks half the view (MSNET on Bonn: 4.3 ms per frame at 1). The networks' masks are
    upsampled bilinearly from 256x192 (MSNET, with `segmenter.guided_radius` 0, the default) or 257x257 (the
    teacher), so 2 px blocks lose none of their detail; the decisions are made on keypoints and 8 px cells,
    and the exclusion band is wider than a block."""
    cluster_cell: int = valid(24, 1, 1_024)
    """Grid cell (pixels) for clustering moving points in the geometry path."""
    cluster_min_points: int = valid(4, 1, 100_000)
    cluster_depth_tol: float = valid(0.25, 0.0, 100.0)
    """Pixels within this (relative) depth of a cluster's median depth belong to the moving region."""
    grow_px: int = valid(0, 0, 256)
    """A dynamic segment is extended by up to this many pixels along its own surface (depth), to cover what
    segmentation missed (0 = off); see `segments.grow_by_depth`. Off: it lifts recall with MSNET, but where
    MSNET marks most of the view it spreads the false positives along the floor and tracking is lost
    (docs/results/dynamic.md, "Tried and not on")."""
    grow_rel_depth: float = valid(0.15, 0.0, 10.0)
    """Relative depth tolerance of that growth around the segment's median depth."""
    local_px: float = valid(48.0, 1.0, 4096.0)
    """Dynamic segments larger than `local_min_area` are also judged locally: a pixel whose `local_k` nearest
    matched points of the segment all lie within this distance and mostly agree with the static scene is kept.
    A segmentation blob that spills from a walking person onto the static table beside them, at the same
    depth, is then removed only where it moves. 0 = off."""
    local_min_area: float = valid(0.05, 0.0, 1.0)
    """Fraction of the image above which a segment is judged locally."""
    local_k: int = valid(5, 1, 1_000)
    local_step_px: int = valid(8, 1, 1_024)
    """Local decisions are made on a grid of this spacing and spread to its cells."""
    dilation_px: int = valid(3, 0, 256)
    """The exclude mask is the dynamic mask dilated by this many pixels (a keypoint on the silhouette describes a
    patch that moves with the object). With true masks a band of half the ORB patch is best, but MSNET's masks
    already spill past people and a wider band starved tracking, hence the narrow default. With the 2026-12-04
    MSNET 15 px helps the augmented proxies (-17 % mean ATE) but costs the real Bonn frames 14 %
    (docs/results/dynamic.md, the exclusion-band tables)."""
    cluster_dilation_px: int = valid(3, 0, 256)
    """The same for the geometric clusters, whose regions are already whole grid cells wide (a wider band
    there removed static features and cost `geometry-only` accuracy on static 7-Scenes)."""


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
    return mask[_pixel(keypoints_xy[:, 1], h), _pixel(keypoints_xy[:, 0], w)] if len(keypoints_xy) \
        else np.zeros(0, bool)


def _refine_from(X: np.ndarray, uv: np.ndarray, K: np.ndarray, T_init: np.ndarray, config: CullingConfig,
                 gates: tuple[float, ...] = (8.0, 3.0, 1.0)) -> tuple[np.ndarray, np.ndarray] | None:
    """(rvec, tvec): the predicted pose T_init refined by Levenberg-Marquardt on the points X (N,3) m seen at
    uv (N,2) px that it already explains (once per gate, in multiples of `pnp_px`), or None when most disagree.
    ~10x cheaper than RANSAC, and it converges to the motion of the points near the prediction."""
    rvec, tvec = cv2.Rodrigues(T_init[:3, :3])[0], T_init[:3, 3].reshape(3, 1).copy()
    # the prediction can be several pixels off: refine on a wide gate first, then tighten it
    for gate in gates:
        inl = reprojection_px(X, uv, K, rvec, tvec) < gate * config.pnp_px
        if inl.sum() < max(6, config.min_pose_support * len(X)):
            return None
        rvec, tvec = cv2.solvePnPRefineLM(X[inl], uv[inl], K, None, rvec, tvec)
    support = (reprojection_px(X, uv, K, rvec, tvec) < config.pnp_px).mean()
    return (rvec, tvec) if support >= config.min_pose_support else None


def _relative_pose(X: np.ndarray, uv: np.ndarray, K: np.ndarray, T_init: np.ndarray | None,
                   config: CullingConfig, segmented: bool) -> tuple[np.ndarray, np.ndarray] | None:
    """(rvec, tvec) of the current camera from previous-frame points X (N,3) m seen at uv (N,2) px: the
    predicted pose refined (`_refine_from`) when there is one and most points agree with it, else PnP-RANSAC's
    when enough agree with that (`min_pose_support`); None: no depth test for this frame."""
    if T_init is not None:
        pose = _refine_from(X, uv, K, T_init, config)
        if pose is not None:
            return pose
    got = sqpnp_ransac(X, uv, K, config.pnp_px, 300, 6, config.usac, segmented and config.ap3p_samples)
    if got is None or (segmented and len(got[2]) < config.min_pose_support * len(X)):
        return None
    return got[0], got[1]


def _scores(p_prev, p_cur, static, prev_depth, K, config, T_init=None, segmented=False,
            pred_init=None) -> np.ndarray | None:
    """Motion score (N,) in epipolar pixels; inf-free, 0 where nothing could be measured. None when `segmented`,
    without a confirmed prediction (`T_init`), the depth test finds no pose (see `min_pose_support`).
    `pred_init` (N, 2) px: where `T_init` puts the matches' previous keypoints (guided matching computed it)."""
    depth_test = config.use_depth and prev_depth is not None and K is not None
    pose = None
    if depth_test:
        h, w = prev_depth.shape
        z = prev_depth[_pixel(p_prev[:, 1], h), _pixel(p_prev[:, 0], w)]
        has = z > 0
        X = backproject(p_prev, z, K)  # (N, 3) previous-camera points; meaningful where `has`
        usable = _spread(np.flatnonzero(has & static), config.fit_max_points)
        if len(usable) >= 6:
            pose = _relative_pose(X[usable], p_cur[usable].astype(np.float64), K, T_init, config, segmented)
        if pose is None and segmented and T_init is None:
            return None
    F = _fundamental(p_prev[static], p_cur[static], pose, K, config)
    predicted = config.prediction_veto and T_init is not None and prev_depth is not None and K is not None
    if F is None and not predicted:
        return np.zeros(len(p_prev))
    # Without F (fewer than 8 matches outside the segments) a confirmed prediction alone scores the points.
    score = epipolar_distance(F, p_prev, p_cur) if F is not None else np.full(len(p_prev), np.inf)
    if depth_test:
        if pose is not None:
            err = reprojection_px(X[has], p_cur[has], K, *pose)
            score[has] = np.maximum(score[has], err / config.reprojection_scale)
        if config.prediction_veto and T_init is not None and has.any():
            # refined only where segments hold nearly all matches (see `refine_prediction_below`)
            refine = static.mean() < config.refine_prediction_below
            T_veto = _veto_pose(X, p_cur, has, K, T_init, config) if refine else T_init
            pred = pred_init[has] if T_veto is T_init and pred_init is not None else \
                predict_positions(p_prev[has], z[has], T_veto, K)
            score[has] = np.fmin(score[has], np.linalg.norm(pred - p_cur[has], axis=1))  # NaN (behind) = no veto
    score[np.isinf(score)] = 0.0  # not measurable
    return score


def _fundamental(p_prev, p_cur, pose, K, config) -> np.ndarray | None:
    """F (3x3) of the static matches (N, 2) px: seeded by the depth test's pose (rvec, tvec) when there is one
    (see `seed_fundamental`), else by RANSAC; None with fewer than 8 matches."""
    if pose is not None and K is not None and config.seed_fundamental < 1.0:
        seed = fundamental_of_pose(cv2.Rodrigues(pose[0])[0], pose[1], K)
        F = fundamental_from_seed(p_prev, p_cur, seed, config.ransac_px, config.seed_fundamental)
        if F is not None:
            return F
    return fundamental_ransac(p_prev, p_cur, config.ransac_px, usac=config.usac)


def _veto_pose(X, p_cur, has, K, T_init, config) -> np.ndarray:
    """4x4 T_cur_prev for the prediction veto: the prediction refined on the matched points X (N,3) m that have
    depth (`has`) and are seen at p_cur (N,2) px (the static majority pulls it onto the scene's motion; see
    `refine_prediction_below`), or the prediction itself."""
    idx = _spread(np.flatnonzero(has), config.fit_max_points)
    if len(idx) < 6:
        return T_init
    # tight gates: movers within a wide first gate pull the pose along with the scene
    pose = _refine_from(X[idx], p_cur[idx].astype(np.float64), K, T_init, config, gates=(3.0, 1.0))
    if pose is None:
        return T_init
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = cv2.Rodrigues(pose[0])[0], pose[1].ravel()
    return T


def _local_decisions(labels, dynamic, moving_label, point_label, xi, yi, scores, thr_label, config) -> np.ndarray:
    """`dynamic` (H, W) with the static-looking parts of large dynamic segments kept (see `local_px`);
    `thr_label` (L+1,) is each segment's Δd."""
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
        idx = PointGrid.of(np.stack([xi[on], yi[on]], 1), config.local_px).nearest(q, config.local_px, config.local_k)
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


def _spread(idx: np.ndarray, n: int) -> np.ndarray:
    """At most `n` of `idx`, evenly spaced (deterministic, and spread over the keypoint order)."""
    return idx if len(idx) <= n else idx[np.linspace(0, len(idx) - 1, n).astype(int)]


def _geometric_clusters(p_cur, moving, depth, covered, config) -> list[np.ndarray]:
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


def cull_frame(kp_prev: np.ndarray, desc_prev: np.ndarray, kp_cur: np.ndarray, desc_cur: np.ndarray,
               depth_cur: np.ndarray, potentially_dynamic: np.ndarray | None, pose_cov: np.ndarray | None,
               config: CullingConfig = CullingConfig(), prev_depth: np.ndarray | None = None,
               K: np.ndarray | None = None, T_cur_prev: np.ndarray | None = None) -> CullingResult:
    """Judge the objects of the current frame.

    `kp_*` (N, 2) pixel coordinates (x, y) with ORB `desc_*` (N, 32) uint8; `depth_cur` float32 m (H, W);
    `potentially_dynamic` bool (H, W) from segmentation (None in geometry-only mode); `pose_cov` the 6x6
    covariance of the previous pose estimate (for Δd); `prev_depth` + `K` enable the reprojection test;
    `T_cur_prev` (4x4, X_cur = T X_prev), the predicted relative pose, enables guided matching. With
    segmentation that leaves no segment, nothing is matched (`CullingResult.without_objects`).
    """
    h, w = depth_cur.shape
    entropy = motion_entropy(pose_cov)
    thr = adaptive_threshold(entropy, config.threshold)
    use_sem = config.use_segmentation and potentially_dynamic is not None
    labels = split_segments(potentially_dynamic, depth_cur, config.min_segment_area, config.depth_jump,
                            config.segment_step) \
        if use_sem and potentially_dynamic is not None else np.zeros((h, w), np.int32)
    if use_sem and not config.detect_unknown and not labels.any():
        empty = np.zeros((h, w), bool)
        return CullingResult(empty, empty, [], thr, entropy, 0, np.zeros(0), np.zeros((0, 2)), without_objects=True)
    if config.judge_marks_above > 0 and use_sem and potentially_dynamic is not None and not config.detect_unknown \
            and potentially_dynamic.mean() <= config.judge_marks_above:  # off (0): no pass over the mask
        return _trusted_marks(labels, thr, entropy, config)
    # Keypoints on objects are matched exhaustively (a search radius would keep only their small motions and
    # bias the decision towards "static"); the static rest, when a pose is predicted, by the guided search.
    on_object = labels[_pixel(kp_cur[:, 1], h), _pixel(kp_cur[:, 0], w)] > 0 if use_sem else None
    m = _match(kp_prev, desc_prev, kp_cur, desc_cur, on_object, prev_depth, K, T_cur_prev, config)
    p_prev, p_cur = kp_prev[m.prev_idx].astype(np.float64), kp_cur[m.cur_idx].astype(np.float64)
    xi, yi = _pixel(p_cur[:, 0], w), _pixel(p_cur[:, 1], h)
    point_label = labels[yi, xi]
    # Refining the predicted pose needs a clean static set; without segments moving points are in it, and a
    # wide first gate would let them pull the pose along (RANSAC instead).
    T_init = T_cur_prev if m.guided and use_sem else None
    pred = m.pred[m.prev_idx] if m.pred is not None and T_init is not None else None
    scores = _scores(p_prev, p_cur, point_label == 0, prev_depth, K, config, T_init, use_sem, pred) \
        if len(p_prev) >= 8 else np.zeros(len(p_prev))
    judged = scores is not None  # False: no segment can be judged (see `min_pose_support`)
    if scores is None:
        scores = np.zeros(len(p_prev))
    decisions = []
    n_labels = int(labels.max())
    moving_label = np.zeros(n_labels + 1, bool)
    thr_label = np.full(n_labels + 1, thr)
    object_level = config.threshold.mode == "object" and prev_depth is not None and K is not None
    z_prev = prev_depth[_pixel(p_prev[:, 1], prev_depth.shape[0]), _pixel(p_prev[:, 0], prev_depth.shape[1])] \
        if object_level and prev_depth is not None else None
    # each segment's scores, ascending: one sort for all segments instead of a mask and a quantile per segment
    order = np.lexsort((scores, point_label))
    sorted_scores = scores[order]
    starts = np.concatenate([[0], np.cumsum(np.bincount(point_label, minlength=n_labels + 1))])
    for lab in range(1, n_labels + 1):
        s = sorted_scores[starts[lab]:starts[lab + 1]]
        by_object = False
        if z_prev is not None and K is not None:
            on = point_label == lab
            sel = on & (z_prev > 0)
            motion = estimate_object_motion(backproject(p_prev[sel], z_prev[sel], K), p_cur[sel], K, T_cur_prev,
                                            config.object_motion)
            if motion is not None:
                thr_label[lab] = object_threshold(motion.cov, config.threshold)[0]
                by_object = True
        if len(s) < config.min_points or not judged:
            moving = config.undecided_dynamic
        else:
            moving = quantile_of_sorted(s, config.segment_quantile) > thr_label[lab]
        decisions.append(SegmentDecision(lab, "semantic", len(s), median_of_sorted(s) if len(s) else 0.0, moving,
                                         float(thr_label[lab]), by_object))
        moving_label[lab] = moving
    if config.grow_px > 0 and moving_label.any():
        # the grown pixels join their segment, so the local decisions below judge them with its points
        labels = labels.copy()
        for grow_lab in np.flatnonzero(moving_label):
            grown = grow_by_depth(labels == grow_lab, depth_cur, config.grow_px, config.grow_rel_depth,
                                  config.depth_jump)
            labels[grown & (labels == 0)] = grow_lab
        point_label = labels[yi, xi]
    # one pass over the image for all segments (none when nothing moves)
    dynamic = pixels_of(labels, moving_label) if moving_label.any() else np.zeros((h, w), bool)
    if config.local_px > 0 and n_labels and judged:
        dynamic = _local_decisions(labels, dynamic, moving_label, point_label, xi, yi, scores, thr_label, config)
    exclude = dilate_disc(dynamic, config.dilation_px)
    if config.detect_unknown or not use_sem:
        moving_pts = scores > thr
        clusters = np.zeros_like(dynamic)
        for k, region in enumerate(_geometric_clusters(p_cur, moving_pts, depth_cur, point_label > 0,
                                                       config)):
            inside = region[yi, xi]
            decisions.append(SegmentDecision(-(k + 1), "geometric", int(inside.sum()),
                                             float(np.median(scores[inside])) if inside.any() else 0.0, True,
                                             thr))
            clusters |= region
        dynamic |= clusters
        exclude |= dilate_disc(clusters, config.cluster_dilation_px)
    return CullingResult(dynamic, exclude, decisions, thr, entropy, len(p_prev), scores, p_cur, m.guided, judged)


def _trusted_marks(labels: np.ndarray, thr: float, entropy: float | None, config: CullingConfig) -> CullingResult:
    """Every segment of `labels` (H, W) int32 dynamic, unjudged (see `judge_marks_above`)."""
    dynamic = labels > 0
    decisions = [SegmentDecision(lab, "semantic", 0, 0.0, True, thr) for lab in range(1, int(labels.max()) + 1)]
    return CullingResult(dynamic, dilate_disc(dynamic, config.dilation_px), decisions, thr, entropy, 0, np.zeros(0),
                         np.zeros((0, 2)), marks_trusted=True)


@dataclass(frozen=True)
class _FrameMatches(Matches):
    guided: bool = False
    pred: np.ndarray | None = None
    """(N_prev, 2) px: every previous keypoint where the predicted pose puts it (guided matching only)."""


def _pixel(coord: np.ndarray, size: int) -> np.ndarray:
    return np.clip(np.round(coord).astype(int), 0, size - 1)


def _near_box(pred: np.ndarray, pts: np.ndarray, margin: float) -> np.ndarray:
    """Indices of predicted positions (N,2) within `margin` px of the bounding box of `pts` (M,2)."""
    if len(pts) == 0:
        return np.zeros(0, int)
    lo, hi = pts.min(0) - margin, pts.max(0) + margin
    with np.errstate(invalid="ignore"):
        return np.flatnonzero(((pred >= lo) & (pred <= hi)).all(1))


def _match(kp_prev, desc_prev, kp_cur, desc_cur, on_object, prev_depth, K, T_cur_prev, config) -> _FrameMatches:
    """Guided matching when a relative pose is predicted and enough guided matches are found, else brute force.

    With segments (`on_object` (M,) bool), the current keypoints on objects are brute-forced against the
    previous keypoints predicted near them (giving way to a nearly as good guided match, `prefer_static_within`)
    and the rest are guided. Without (`on_object` None, geometry-only) everything is guided first, then what is
    left on both sides is brute-forced: the moving points a search radius misses are exactly what the geometric
    path looks for."""
    guided = np.flatnonzero(~on_object) if on_object is not None else np.arange(len(kp_cur))
    if T_cur_prev is not None and K is not None and prev_depth is not None and len(kp_prev) and len(kp_cur):
        h, w = prev_depth.shape
        z = prev_depth[_pixel(kp_prev[:, 1], h), _pixel(kp_prev[:, 0], w)]
        uv_prev = kp_prev.astype(np.float64)
        pred = predict_positions(uv_prev, z, T_cur_prev, K)  # (N, 2) px, once for every search below

        def search(cur: np.ndarray, prev: np.ndarray | None = None) -> Matches:
            """Guided matches of the current keypoints `cur` among the previous ones `prev` (None = all)."""
            sel = np.s_[:] if prev is None else prev  # all: views, no copies
            index = KeypointIndex.of_points(kp_cur[cur], desc_cur[cur], grid=True)
            m = match_guided(uv_prev[sel], z[sel], desc_prev[sel], index,
                             T_cur_prev, K, config.guided_radius_px, config.match_max_distance, pred=pred[sel])
            return m if prev is None else Matches(prev[m.prev_idx], m.cur_idx)

        g = search(guided)
        confirmed = len(g.prev_idx) >= config.guided_min_matches
        if not confirmed and on_object is not None and config.confirm_on_objects:
            # Segments covering most of the view leave too few keypoints outside them to confirm the
            # prediction; the static scene under a wrong mask confirms it as well as the scene outside.
            confirmed = len(search(np.arange(len(kp_cur))).prev_idx) >= config.guided_min_matches
        if confirmed:
            g_cur = guided[g.cur_idx]
            if on_object is not None:
                rest_cur = np.flatnonzero(on_object)
                rest_prev = _near_box(pred, kp_cur[rest_cur], config.object_margin_px)
            else:
                rest_cur = np.setdiff1d(np.arange(len(kp_cur)), g_cur)
                rest_prev = np.setdiff1d(np.arange(len(kp_prev)), g.prev_idx)
            b = match_orb(desc_prev[rest_prev], desc_cur[rest_cur], config.match_max_distance)
            b_prev, b_cur = rest_prev[b.prev_idx], rest_cur[b.cur_idx]
            if on_object is not None and config.prefer_static_within >= 0 and len(b_cur):
                # only previous keypoints that can land within the search radius (doubled without depth)
                reach = _near_box(pred, kp_cur[b_cur], 2 * config.guided_radius_px)
                b_prev, b_cur = _prefer_static(b_prev, b_cur, search(b_cur, reach), desc_prev, desc_cur,
                                               config.prefer_static_within)
            free = ~np.isin(b_prev, g.prev_idx)  # a previous keypoint matched twice keeps its guided match
            return _FrameMatches(np.concatenate([g.prev_idx, b_prev[free]]),
                                 np.concatenate([g_cur, b_cur[free]]), True, pred)
    m = match_orb(desc_prev, desc_cur, config.match_max_distance)
    return _FrameMatches(m.prev_idx, m.cur_idx, False)


def _prefer_static(b_prev: np.ndarray, b_cur: np.ndarray, near: Matches, desc_prev: np.ndarray,
                   desc_cur: np.ndarray, within: int) -> tuple[np.ndarray, np.ndarray]:
    """Brute-force matches (b_prev, b_cur) (K,) with a current keypoint's previous one replaced by its guided
    match (`near`: indices into `b_cur` and into the previous keypoints) where that one's Hamming distance
    exceeds the brute-force one's by at most `within` (see `prefer_static_within`). A previous keypoint
    claimed twice stays with the first of its current keypoints."""
    pos = near.cur_idx
    d_brute = hamming(desc_prev[b_prev[pos]], desc_cur[b_cur[pos]])
    d_near = hamming(desc_prev[near.prev_idx], desc_cur[b_cur[pos]])
    swap = d_near <= d_brute + within
    b_prev = b_prev.copy()
    b_prev[pos[swap]] = near.prev_idx[swap]
    first = np.sort(np.unique(b_prev, return_index=True)[1])
    return b_prev[first], b_cur[first]
