"""Pipeline configuration: one typed dataclass per core section, composed into `PipelineConfig`.

A job stores `PipelineConfig.to_dict()`; `PipelineConfig.from_dict()` rebuilds it (unknown keys are errors).
Stages plug their own sections in without editing this file: a config carries them in `extra` (a catalog,
`worker.slam.catalog`, builds configs that hold every shipped stage's section), and `from_dict`/`to_dict`
understand the sections the config carries.
"""
from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from worker.slam.config_values import apply_values, expand_dotted
from worker.slam.errors import ConfigError


def valid(default: Any, lo: float, hi: float, *, below: str | None = None, at_most: str | None = None) -> Any:
    """A numeric field's default and its documented valid range ``lo..hi`` (inclusive), checked on every
    override by :func:`_apply` and published for the api in ``formats/settings_ranges.json``
    (``worker.slam.ranges``): a value outside it never reaches a native library (``n_levels: 0``
    segfaulted OpenCV's ORB).

    ``below``/``at_most`` name the sibling field that bounds this one from above (``<`` / ``<=``): the lower
    end of a pair whose ranges each hold but contradict each other (a minimum depth above the maximum)."""
    meta: dict[str, Any] = {"range": (lo, hi)}
    for key, other in (("below", below), ("at_most", at_most)):
        if other is not None:
            meta[key] = other
    return field(default=default, metadata=meta)


@dataclass
class FeatureConfig:
    n_features: int = valid(1000, 10, 100_000)
    """ORB keypoints per frame after grid balancing."""
    scale_factor: float = valid(1.2, 1.01, 4.0)
    """Scale between pyramid levels."""
    n_levels: int = valid(8, 1, 16)
    """Pyramid levels."""
    overdetect: int = valid(3, 1, 50)
    """Corners detected per kept keypoint before the grid balances them; more helped the synthetic proxies but
    lost on real footage. Measured: docs/results/settings.md#features-overdetect"""
    fast_threshold: int = valid(10, 1, 255)
    """FAST threshold; low, so weakly textured grid cells still get corners (the grid keeps the best)."""
    grid_cell_px: int = valid(40, 4, 1_024)
    """Side of the grid cells that balance keypoints across the image."""
    min_depth_m: float = valid(0.1, 0.0, 100.0, below="max_depth_m")
    """Depth below this is treated as invalid."""
    max_depth_m: float = valid(6.0, 0.01, 1000.0)
    """Depth above this is treated as invalid (noisy far range)."""
    depth_edge_radius_px: int = valid(0, 0, 64)
    """> 0: keypoints within this many pixels of a depth edge or hole get no depth (colour/depth misregistration)."""
    depth_sigma_per_m2: float = valid(0.0, 0.0, 1.0)
    """> 0: depth weighed per keypoint (`depth_weights`); off: docs/results/jitter.md#depth-weighed-per-keypoint"""


@dataclass
class TrackingConfig:
    search_radius_px: float = valid(12.0, 0.5, 500.0)
    """Projection-search window radius at octave 0 (scaled by the keypoint's scale)."""
    refine_radius_px: float = valid(4.0, 0.5, 500.0)
    """Radius of the second, local-map search after the first pose estimate."""
    max_hamming: int = valid(80, 0, 256)
    """Largest descriptor distance accepted by projection search."""
    ratio: float = valid(0.9, 0.1, 1.0)
    """Best/second-best distance ratio in projection search (1 disables the test)."""
    min_matches: int = valid(30, 4, 100_000)
    """Fewer inliers than this after pose optimisation means tracking is lost."""
    virtual_baseline_m: float = valid(0.08, 0.0001, 10.0)
    """Virtual stereo baseline of the depth (right-image) residual, i.e. how much keypoint depth weighs in pose
    optimisation: ORB-SLAM2's ~0.08 (TUM), for cameras whose depth is registered to colour
    (`Camera.depth_registered`). Measured: docs/results/settings.md#tracking-virtual_baseline_m"""
    unregistered_baseline_m: float = valid(0.01, 0.0001, 10.0)
    """The same for cameras whose depth is not registered to colour (7-Scenes): a keypoint's depth may belong
    to a neighbouring surface, so it weighs less. Measured: docs/results/settings.md#tracking-unregistered_baseline_m"""
    huber_px: float = valid(2.45, 0.01, 1000.0)
    """Huber threshold (pixels) of the robust kernel, sqrt of the 2-dof 95% chi-square (5.99)."""
    ba_rounds: int = valid(4, 1, 100)
    """Motion-only BA rounds; outliers are re-classified after each round."""
    ba_iterations: int = valid(8, 1, 1_000)
    """Gauss-Newton iterations per round."""
    established_frames: int = valid(10, 0, 100_000)
    """Each pose is also solved with every match weighted by how established its map point is (matched in n
    frames: weight min(n / N, 1), at least 1 / N), and replaced by that solve when they differ by more than
    `established_disagree_m`: people walking together drag the plain solve, long-still points do not. 0 = off.
    Measured: docs/results/settings.md#tracking-established_frames"""
    established_disagree_m: float = valid(0.01, 0.0, 10.0)
    """Translation between the plain and the weighted pose beyond which the weighted one is taken."""
    rescue_with_held_back: bool = True
    """A frame that cannot be tracked on the keypoints culling kept (segmentation marking most of the view) is
    tracked again with the held-back ones added; of those only the map points' inliers stay, so the map's
    established static points decide which marked parts are static. A first frame whose kept keypoints cannot
    start a map starts it on all of them. Counted as `rescued_frames`.
    Measured: docs/results/settings.md#tracking-rescue_with_held_back"""
    retry_from_last_pose: bool = True
    """A frame that cannot be tracked from the constant-velocity prediction (held-back keypoints included) is
    tracked again from the last frame's pose before relocalisation, as ORB-SLAM falls back from its motion
    model to the reference keyframe: a velocity taken from a few badly tracked frames overshoots. Counted as
    `last_pose_retries`."""
    local_map_keyframes: int = valid(12, 1, 1_000)
    """Covisible keyframes whose points form the local map."""
    keyframe_max_frames: int = valid(20, 1, 100_000)
    """Insert a keyframe at least this often (frames)."""
    keyframe_min_frames: int = valid(0, 0, 100_000, at_most="keyframe_max_frames")
    """Never insert keyframes closer than this (frames)."""
    keyframe_ratio: float = valid(0.75, 0.0, 1.0)
    """Insert a keyframe when the tracked points fall below this fraction of the reference keyframe's."""
    keyframe_min_close: int = valid(100, 0, 100_000)
    """Insert a keyframe when fewer close points than this are tracked (RGB-D rule of ORB-SLAM2)."""
    close_depth_m: float = valid(3.5, 0.01, 1000.0)
    """Points closer than this count as 'close' (well-constrained depth)."""
    reloc_keyframes: int = valid(10, 0, 1_000)
    """Recent keyframes tried by relocalisation (plus the best descriptor matches)."""
    reloc_min_inliers: int = valid(30, 4, 100_000)
    """PnP-RANSAC inliers needed to accept a relocalisation."""
    init_min_points: int = valid(150, 4, 100_000)
    """A map starts (first keyframe, or a new map after a loss) only on a frame whose depth gives at least
    this many new map points: 5x `min_matches`, since culling removes many new points (ORB-SLAM2 waits for
    500 keypoints). Measured: docs/results/settings.md#tracking-init_min_points"""
    new_map_after_lost: int = valid(1, 1, 100_000)
    """Consecutive frames that neither track nor relocalise before a new map starts at the motion model's
    pose (constant-velocity bridge: same world frame, no shared points until a loop connects them)."""
    reset_max_keyframes: int = valid(5, 0, 100_000)
    """A map with at most this many keyframes that loses tracking is discarded (its points killed) when the
    new map starts, as ORB-SLAM2 resets young maps; older maps stay for relocalisation and loop closure."""


@dataclass
class MappingConfig:
    local_ba: bool = True
    """Run local bundle adjustment when a keyframe is inserted."""
    local_ba_keyframes: int = valid(8, 1, 1_000)
    """Keyframes optimised by local BA (the newest and its best covisible ones)."""
    local_ba_iterations: int = valid(6, 1, 1_000)
    """Levenberg-Marquardt iterations of local BA."""
    local_ba_every: int = valid(1, 1, 1_000)
    """Run local BA every N keyframes."""
    cull_min_found_ratio: float = valid(0.25, 0.0, 1.0)
    """Points found in fewer than this fraction of the frames they should be visible in are culled."""
    cull_grace_keyframes: int = valid(3, 0, 1_000)
    """Points younger than this (keyframes) are not culled by observation count."""
    new_point_max_depth_m: float = valid(4.0, 0.01, 1000.0)
    """New map points are created from keyframe depth up to this distance."""
    triangulate_neighbours: int = valid(0, 0, 1_000)
    """Covisible keyframes each new keyframe triangulates new points with, for keypoints that got none from
    depth (no depth, or beyond `new_point_max_depth_m`); 0 turns triangulation off, the default: it helped the
    proxies and hurt real footage. Measured: docs/results/settings.md#mapping-triangulate_neighbours"""
    triangulate_min_parallax_deg: float = valid(1.0, 0.0, 90.0)
    """Smallest angle between the two viewing rays of a triangulated point."""
    fuse_neighbours: int = valid(0, 0, 1_000)
    """Covisible keyframes each new keyframe fuses map points with (ORB-SLAM2's SearchInNeighbors with 10: a
    keypoint matched to a neighbour's point gains the observation); 0 turns it off. Off: it helped one preset
    and hurt another. Measured: docs/results/settings.md#mapping-fuse_neighbours"""
    fuse_radius_px: float = valid(3.0, 0.5, 100.0)
    """Search radius of fusion at octave 0 (grows with the octave's scale)."""
    fuse_merge: bool = False
    """Fusion also merges two points found on one keypoint, as ORB-SLAM2 does (the better observed stays)."""
    final_global_ba: bool = True
    """Bundle-adjust all keyframes and points once at the end (the first keyframe fixed)."""
    global_ba_iterations: int = valid(10, 0, 1_000)
    """Levenberg-Marquardt iterations of the final global BA."""
    refit_frames: bool = True
    """At the end, re-solve every tracked non-keyframe frame's pose by motion-only BA against the final map
    points it matched (`mapping/frame_refit.py`), not the points as they were when it was tracked. Keeps ~6 kB
    per frame until the end. Measured: docs/results/settings.md#mapping-refit_frames"""
    smooth_frames: bool = True
    """After the refit, solve all frames' poses together under a constant-velocity motion prior, each frame
    weighted by its refit's pose information (`mapping/smoothing.py`): removes the per-frame jitter of poses
    solved alone (needs `refit_frames`). Measured: docs/results/settings.md#mapping-smooth_frames"""
    smooth_accel_sigma: float = valid(0.15, 0.001, 1000.0)
    """Motion prior of the smoother: white-noise acceleration, m/s^2 per sqrt(Hz) (larger: follows each
    frame's own solve more closely; Huber-weighted, so real jolts pass). 0.05-0.25 scored alike on the synthetic
    room, augmented seeds and 7-Scenes; 1.0 kept much of the jitter.
    Measured: docs/results/settings.md#mapping-smooth_accel_sigma"""
    smooth_angular_sigma: float = valid(0.5, 0.001, 1000.0)
    """The same for rotation, rad/s^2 per sqrt(Hz). Measured: docs/results/settings.md#mapping-smooth_angular_sigma"""


@dataclass
class LoopConfig:
    enabled: bool = True
    """Detect revisits and correct them with a pose graph."""
    min_keyframe_gap: int = valid(10, 1, 100_000)
    """Candidates must be at least this many keyframes older than the query."""
    min_matches: int = valid(20, 4, 100_000)
    """Descriptor matches (under one vocabulary node, ratio test) and PnP-RANSAC inliers that make a candidate
    (ORB-SLAM2's 20)."""
    min_inliers: int = valid(50, 4, 100_000)
    """Inliers after the loop side's points are projected in and the pose refined that confirm a loop."""
    consistency: int = valid(3, 0, 100)
    """A candidate's covisibility group must have been a candidate for this many keyframes in a row
    (ORB-SLAM2's 3): one look-alike view never closes a loop."""
    vocabulary: str = ""
    """ORB vocabulary file (.npz of `vtdslam train-vocab`); empty: the shipped one
    (worker/slam/features/data/VOCABULARY.md)."""
    descriptors_per_keyframe: int = valid(400, 10, 100_000)
    """Unused since the trained vocabulary (issue 58: every descriptor of a keyframe is quantised); kept so that
    saved configurations that set it still load."""
    min_correction_m: float = valid(0.02, 0.0, 100.0)
    """Loops whose correction is smaller than this (and < 1 degree) are accepted but not applied."""


@dataclass
class DenseConfig:
    enabled: bool = True
    """Fuse keyframes into a coloured point cloud (`map.ply`)."""
    stride: int = valid(4, 1, 64)
    """Pixel stride of the kept keyframe RGB-D (4 -> 160x120 at 640x480)."""
    voxel_m: float = valid(0.01, 0.001, 10.0)
    """Voxel size of the filter that merges the back-projected keyframes."""
    max_depth_m: float = valid(4.0, 0.01, 1000.0)
    """Depth beyond this is not fused."""
    edge_rel: float = valid(0.05, 0.0, 1.0)
    """Drop pixels whose 3x3 neighbourhood jumps by more than this fraction of depth (flying pixels); 0 keeps all."""
    method: str = "points"
    """`points`: back-projected keyframes merged per voxel (keeps every surface ever seen); `tsdf`: a TSDF
    volume, where later views carve out what moved away (`worker.slam.mapping.tsdf`)."""
    tsdf_trunc_voxels: float = valid(4.0, 1.0, 100.0)
    """TSDF truncation band in voxels (`method: tsdf`)."""
    carve: bool = True
    """Drop map points that other frames' measured depth sees through: what was there only for a while, e.g. a
    person segmentation missed (`worker.slam.mapping.carve`). Measured: docs/results/settings.md#dense-carve"""
    carve_every: int = valid(3, 0, 1000)
    """Every n-th tracked frame's depth votes in carving at its final pose (0: the keyframes only): frames
    between keyframes see behind people. Measured: docs/results/settings.md#dense-carve_every"""
    carve_max_views: int = valid(1000, 1, 100_000)
    """At most this many frames kept for carving (77 kB each at 640x480, stride 4); a longer run thins them."""
    carve_min_through: int = valid(3, 1, 1000)
    """Views that must see through a point before it is dropped (one is not enough: a single bad depth frame
    or pose would carve static surfaces)."""
    carve_majority: bool = False
    """Also require that the point was seen through more often than seen (the earlier rule): keeps people who
    stay in view for many keyframes, so off. Measured: docs/results/settings.md#dense-carve_majority"""


@dataclass
class EvalConfig:
    max_diff_s: float = valid(0.02, 0.0001, 10.0)
    """Timestamp association tolerance against ground truth."""
    rpe_delta_s: float = valid(1.0, 0.001, 1000.0)
    """RPE interval."""


_CORE = ("features", "tracking", "mapping", "loop", "dense", "eval")


def check_section(name: str, cls: type) -> None:
    """An extra stage config must be a dataclass with defaults, under a name no core part uses."""
    if name in _CORE or name in ("name", "stages"):
        raise ConfigError(f"config section name {name!r} is reserved")
    if not dataclasses.is_dataclass(cls):
        raise ConfigError(f"config section {name!r} must be a dataclass")


@dataclass
class PipelineConfig:
    name: str = "custom"
    """Preset this config was built from (informational)."""
    stages: list[str] = field(default_factory=list)
    """Ordered per-frame stages run before tracking (names of a catalog's stages, `worker.slam.catalog`)."""
    features: FeatureConfig = field(default_factory=FeatureConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    mapping: MappingConfig = field(default_factory=MappingConfig)
    loop: LoopConfig = field(default_factory=LoopConfig)
    dense: DenseConfig = field(default_factory=DenseConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    extra: dict[str, Any] = field(default_factory=dict)
    """The stages' sections this config knows, by name, in snapshot order (instances of their dataclasses;
    `with_sections` or a catalog's `base_config()` fills them with defaults)."""

    @classmethod
    def with_sections(cls, sections: Mapping[str, type]) -> PipelineConfig:
        """Defaults, plus the extra `sections` (name -> dataclass with defaults) in their order: the order of
        a snapshot's keys after the core ones."""
        for name, section_cls in sections.items():
            check_section(name, section_cls)
        return cls(extra={name: section_cls() for name, section_cls in sections.items()})

    def section(self, name: str) -> Any:
        """A core section or one of the extra sections this config carries."""
        if name in _CORE:
            return getattr(self, name)
        if name not in self.extra:
            raise ConfigError(f"unknown config section {name!r}")
        return self.extra[name]

    def to_dict(self) -> dict:
        out: dict[str, Any] = {"name": self.name, "stages": list(self.stages)}
        for sec in _CORE:
            out[sec] = dataclasses.asdict(getattr(self, sec))
        for sec, value in self.extra.items():  # every section the config carries, so a job's snapshot is complete
            out[sec] = dataclasses.asdict(value)
        return out

    @classmethod
    def from_dict(cls, d: dict, base: PipelineConfig | None = None) -> PipelineConfig:
        """Build from a (possibly partial) snapshot; missing values come from `base` (default: the core defaults
        alone, so a snapshot with stage sections needs a base that carries them: `Catalog.config_from_dict`)."""
        cfg = copy.deepcopy(base) if base is not None else cls()
        return cfg.with_overrides(d)

    def with_overrides(self, overrides: dict) -> PipelineConfig:
        """A copy with nested (`{"tracking": {"ratio": 0.8}}`) or dotted (`{"tracking.ratio": 0.8}`) values."""
        cfg = copy.deepcopy(self)
        for key, val in expand_dotted(overrides).items():
            if key == "name":
                cfg.name = str(val)
            elif key == "stages":
                if not isinstance(val, (list, tuple)) or not all(isinstance(s, str) for s in val):
                    raise ConfigError("stages must be a list of stage names")
                cfg.stages = list(val)
            elif key in _CORE or key in cfg.extra:
                if not isinstance(val, dict):
                    raise ConfigError(f"config section {key!r} must be an object")
                target = cfg.section(key)
                updated = apply_values(target, val, key)
                if key in _CORE:
                    setattr(cfg, key, updated)
                else:
                    cfg.extra[key] = updated
            else:
                raise ConfigError(f"unknown config section {key!r}; known: {sorted(_CORE + tuple(cfg.extra))}")
        return cfg
