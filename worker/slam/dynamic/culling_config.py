"""The settings of dynamic culling (`culling.culling` in a config), in a module of their own so that every
concern of culling (matching, relative pose, scoring, decisions) can import them without importing the
orchestrator (`culling.py`)."""
from __future__ import annotations

from dataclasses import dataclass, field

from worker.slam.config import valid
from worker.slam.dynamic.object_motion import ObjectMotionConfig
from worker.slam.dynamic.threshold import ThresholdConfig


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
    """F's RANSAC and the depth test's PnP-RANSAC fallback by OpenCV's USAC instead of classic RANSAC: cheaper
    on the slowest frames but less accurate, so off. Measured: docs/results/settings.md#culling-usac"""
    seed_fundamental: float = valid(0.5, 0.0, 1.0)
    """When the depth test has its pose, F is fitted by least squares to the static matches that pose's own F
    explains within `ransac_px` (`epipolar.fundamental_from_seed`), if at least this fraction of them do;
    else, and without a pose, by RANSAC (1 = always RANSAC). The pose plays RANSAC's best hypothesis: cheaper,
    the same accuracy. Measured: docs/results/settings.md#culling-seed_fundamental"""
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
    on repeated texture exhaustive matching sometimes picks a wrong match far away.
    Measured: docs/results/settings.md#culling-prefer_static_within"""
    confirm_on_objects: bool = True
    """When too few keypoints outside the segments match the prediction, count the guided matches of all
    keypoints instead. Segmentation that marks most of the view (MSNET on the synthetic room) otherwise leaves
    the prediction unconfirmed, so the prediction veto is off exactly when F, fitted on the few points left
    outside, is least reliable. Measured: docs/results/settings.md#culling-confirm_on_objects"""
    use_depth: bool = True
    """Add the reprojection test with the previous frame's depth."""
    pnp_px: float = valid(2.0, 0.01, 100.0)
    """RANSAC threshold of the depth test's PnP; wider lets a wrong motion explain a moving object too."""
    min_pose_support: float = valid(0.5, 0.0, 1.0)
    """The depth test's pose is used only when at least this fraction of the static points agree with it
    (within `pnp_px`): the predicted pose refined (no RANSAC) when it passes, else (with segments) PnP-RANSAC's
    pose when that passes. With segments and without a pose, a frame whose prediction guided matching did not
    confirm cannot be judged (see `undecided_dynamic`): its brute-force matches hold no motion most static
    points agree on (people filling a motion-blurred view), so fitting F to them cost time for scores nothing
    relied on. Without segments (`geometry-only`) the matches include every mover, so a pose's support says
    less, and any RANSAC pose is used as before. Measured: docs/results/settings.md#culling-min_pose_support"""
    ap3p_samples: bool = True
    """With segments, PnP-RANSAC's hypotheses by AP3P on 4 points, then SQPnP on the consensus
    (`pnp.sqpnp_ransac`): about 3x cheaper. `geometry-only`, which needs RANSAC on every frame, keeps SQPnP's
    samples (the change moved its ATEs both ways). Measured: docs/results/settings.md#culling-ap3p_samples"""
    reprojection_scale: float = valid(3.0, 0.01, 100.0)
    """A reprojection error counts as `error / scale` epipolar pixels (depth noise is larger than keypoint noise)."""
    prediction_veto: bool = True
    """With a predicted relative pose that guided matching confirmed, a point's score is at most its
    reprojection error under that prediction: it must move against the tracker's expectation too. F and the
    depth test's pose are fitted on the matches outside the segments, and when segmentation marks most of the
    static view and misses part of a person (MSNET: floor, chairs, red cabinets), that outside set is mostly
    the person; the whole static scene then looks moving and tracking is lost. Where segmentation is right the
    veto can only keep slow movers, so it trades a little there for not losing whole sequences.
    Measured: docs/results/settings.md#culling-prediction_veto"""
    refine_prediction_below: float = valid(0.2, 0.0, 1.0)
    """When fewer than this fraction of the matches lie outside the segments, the prediction veto uses the
    predicted pose refined on all matched points (`relative_pose.refine_from`: LM from the prediction on the
    points it explains, gates of 3 and 1 x `pnp_px`) instead of the raw constant-velocity prediction (0 =
    never). There F and the depth pose, fitted on the few matches outside, are weak and the veto decides, and a
    prediction a few pixels off makes the whole static view look moving.
    Measured: docs/results/settings.md#culling-refine_prediction_below"""
    min_points: int = valid(3, 1, 100_000)
    """A segment needs this many matched points to be judged by geometry."""
    judge_marks_above: float = valid(0.0, 0.0, 1.0)
    """> 0: geometry judges the marked segments only in frames where segmentation marks more than this share of
    the view; below it every marked segment is excluded unjudged and nothing is matched
    (`CullingResult.marks_trusted`): a person who looks still over `lag_frames` is often starting or ending a
    walk. 0 (the default) = the paper: every mark is judged; 0.5 helped the development means but not the
    synthetic rooms, so it stays an option. 1 = never judge: frames whose marks cover most of the view starve.
    Measured: docs/results/settings.md#culling-judge_marks_above"""
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
    segmentation marks half the view (docs/results/settings.md#culling-segment_step). The networks' masks are
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
    MSNET marks most of the view it spreads the false positives along the floor and tracking is lost.
    Measured: docs/results/settings.md#culling-grow_px"""
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
    patch that moves with the object). Narrow: MSNET's masks already spill past people, and a wider band helps
    the augmented proxies but costs real footage. Measured: docs/results/settings.md#culling-dilation_px"""
    cluster_dilation_px: int = valid(3, 0, 256)
    """The same for the geometric clusters, whose regions are already whole grid cells wide (a wider band
    there removed static features and cost `geometry-only` accuracy on static 7-Scenes).
    Measured: docs/results/settings.md#culling-cluster_dilation_px"""
