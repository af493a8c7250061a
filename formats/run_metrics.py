"""The run-metrics schema: what a run's ``metrics.json`` holds, typed, with units.

The pipeline writes it (:func:`format_run_metrics`); the repositories, the batch table, the worker and the
benches read it through :meth:`RunMetrics.from_dict`, the one reader that tolerates old and foreign spellings
(RPE as ``rpe.trans_rmse``/``rpe.rot_rmse`` or ``rpe.rot``; absent keys; strings for numbers). The stored blob and
the api's ``metrics`` stay the file's own content: this schema reads them, it never renames their keys.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from formats.errors import FormatError
from formats.version import PROVENANCE_KEYS

Number = int | float


def number(value: Any) -> Number | None:
    """``value`` if it is a number (ints stay ints: the file is rewritten byte for byte), a numeric string as a
    float, else None (bools, garbage). NaN and inf pass: use :func:`finite` where they must not."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        return value
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return None
    return None


def finite(value: Any) -> float | None:
    """``value`` as a finite float, else None."""
    v = number(value)
    return float(v) if v is not None and math.isfinite(v) else None


def _count(value: Any) -> int | None:
    v = number(value)
    if v is None or isinstance(v, int):
        return v
    return int(v) if math.isfinite(v) else None


def _dict(value: Any) -> dict[str, Any] | None:
    return dict(value) if isinstance(value, Mapping) else None


def _string(value: Any) -> str | None:
    return value if isinstance(value, str) else None


def _strings(value: Any) -> list[str]:
    return [v for v in value if isinstance(v, str)] if isinstance(value, list | tuple) else []


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of a set of errors, in the unit its holder names (ATE: metres; RPE: per interval)."""

    rmse: Number | None = None
    mean: Number | None = None
    median: Number | None = None
    std: Number | None = None
    """Population standard deviation (numpy's default, as TUM's scripts)."""
    max: Number | None = None

    @classmethod
    def from_dict(cls, d: Any) -> ErrorStats | None:
        """None unless ``d`` is a mapping; absent or non-numeric entries are None."""
        if not isinstance(d, Mapping):
            return None
        return cls(*(number(d.get(f.name)) for f in fields(cls)))

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class RpeMetrics:
    """TUM's relative pose error (worker.slam.evaluation.rpe)."""

    mode: str | None = None
    """``fixed-delta``, ``fixed-frames`` or ``all-pairs``."""
    delta_s: Number | None = None
    """Seconds between the two poses of a pair (fixed-delta mode)."""
    delta_frames: int | None = None
    """Poses between the two poses of a pair (fixed-frames mode: 1 = consecutive poses)."""
    max_pairs: int | None = None
    """The sampling bound asked for; 0 = every pair."""
    pairs: int | None = None
    """Pairs evaluated."""
    trans: ErrorStats = field(default_factory=ErrorStats)
    """Translation error, metres per interval."""
    rot_deg: ErrorStats = field(default_factory=ErrorStats)
    """Rotation error, degrees per interval."""

    @classmethod
    def from_dict(cls, d: Any) -> RpeMetrics | None:
        """None unless ``d`` is a mapping. Reads the pipeline's ``{trans: {...}, rot_deg: {...}}`` and the older
        or foreign ``rot: {...}`` and flat ``trans_rmse``/``rot_rmse`` spellings (the only place that does)."""
        if not isinstance(d, Mapping):
            return None

        def stats(flat: str, *nested: str) -> ErrorStats:
            got = next((s for s in map(ErrorStats.from_dict, map(d.get, nested)) if s is not None), ErrorStats())
            return got if d.get(flat) is None else replace(got, rmse=number(d[flat]))

        mode = d.get("mode")
        return cls(mode if isinstance(mode, str) else None, number(d.get("delta_s")), _count(d.get("delta_frames")),
                   _count(d.get("max_pairs")), _count(d.get("pairs")), stats("trans_rmse", "trans"),
                   stats("rot_rmse", "rot_deg", "rot"))

    def to_dict(self) -> dict[str, Any]:
        out = {"mode": self.mode, "delta_s": self.delta_s, "max_pairs": self.max_pairs, "pairs": self.pairs,
               "trans": self.trans.to_dict(), "rot_deg": self.rot_deg.to_dict()}
        if self.delta_frames is not None:
            out["delta_frames"] = self.delta_frames
        return out


@dataclass(frozen=True)
class TruthScores:
    """Scores against a sequence's truth (synthetic or augmented data), from the stages' summaries; None where
    the stage did not run or the sequence has no truth."""

    mask_iou: float | None = None
    """Culled-region IoU against the true moving-object masks (0..1)."""
    feature_precision: float | None = None
    """Share of removed features that were on true movers (0..1)."""
    feature_recall: float | None = None
    """Share of features on true movers that were removed (0..1)."""
    restoration_psnr: float | None = None
    """dB, restored pixels against the true background."""


_COUNTS = ("frames", "tracked", "lost", "relocalisations", "new_maps", "map_merges", "established_switches",
           "rescued_frames", "last_pose_retries", "frames_refit", "frames_smoothed", "keyframes", "map_points",
           "fused_observations", "loops", "loops_applied")
_CORE = (*_COUNTS, "fps", "tracking_fps", "tracking_cpu_ms", "timings_ms", "overlapped_stages", "dense_points",
         "stage_info", "peak_rss_mb", "camera", "preset", "start", "tracked_fraction", "warnings",
         "smoothing_skipped")
_LABELS = ("groundtruth_frame", "ate_against", "ate_corrected_against", "rpe_against")
_EVALUATION = ("ate", "matched_poses", "rpe", *_LABELS, "ate_corrected", "rpe_frame", "evaluation_error")
_PROVENANCE = PROVENANCE_KEYS  # ("version", "commit"): written after the core keys when known


@dataclass
class RunMetrics:
    """A run's ``metrics.json``. Key order on disk: the counters and figures below (always written, null where
    unknown), ``version`` and ``commit`` (both, the commit null outside a git checkout; a run older than them
    has neither), the stages' summaries (:attr:`stages`), then the evaluation (``ate``, ``matched_poses``,
    ``rpe``, ``groundtruth_frame``, the ``*_against`` labels, ``ate_corrected``, ``rpe_frame`` when there is
    ground truth, or ``evaluation_error``), then keys this schema does not know (:attr:`extra`)."""

    frames: int | None = None
    """Frames processed."""
    tracked: int | None = None
    """Frames with a tracked pose."""
    lost: int | None = None
    """Frames without one (``frames - tracked``)."""
    relocalisations: int | None = None
    """Times tracking was lost and found again."""
    new_maps: int | None = None
    map_merges: int | None = None
    established_switches: int | None = None
    rescued_frames: int | None = None
    """Frames tracked thanks to held-back keypoints."""
    last_pose_retries: int | None = None
    frames_refit: int | None = None
    """Frames re-solved against the final map."""
    frames_smoothed: int | None = None
    """Frames the end-of-run smoothing (``mapping.smooth_frames``) moved; 0 when it did not run
    (:attr:`smoothing_skipped` says why); None for runs older than the count."""
    keyframes: int | None = None
    map_points: int | None = None
    """Map points alive at the end."""
    fused_observations: int | None = None
    loops: int | None = None
    """Loops detected."""
    loops_applied: int | None = None
    fps: Number | None = None
    """Frames per second over the frame loop (all stages), wall clock."""
    tracking_fps: Number | None = None
    """Frames per second of tracking alone (1000 / mean tracking ms)."""
    tracking_cpu_ms: Number | None = None
    """Mean CPU milliseconds per frame in tracking (process time)."""
    timings_ms: dict[str, Any] = field(default_factory=dict)
    """Mean wall milliseconds per call, by step (stage names, ``<stage>_wait``, tracking, local_mapping, ...)."""
    overlapped_stages: list[str] = field(default_factory=list)
    """Stages whose ``prepare`` ran ahead on another thread."""
    dense_points: int | None = None
    """Points in the dense map (map.ply)."""
    stage_info: dict[str, Any] = field(default_factory=dict)
    """Per-frame means of the stages' numeric per-frame figures (units as the stage names them)."""
    peak_rss_mb: Number | None = None
    """Peak resident memory of the process, MiB."""
    camera: dict[str, Any] = field(default_factory=dict)
    """The camera the run used (intrinsics in pixels, ``depth_scale`` units per metre)."""
    preset: str | None = None
    start: int | None = None
    """Index of the first frame processed."""
    tracked_fraction: Number | None = None
    """``tracked / frames`` (0..1): below 1, trajectory.txt holds only the tracked frames' poses."""
    warnings: list[str] = field(default_factory=list)
    """What a user should know about the result (frames that were not tracked, ...); empty when nothing."""
    smoothing_skipped: str | None = None
    """Why the end-of-run frame smoothing did not run (``mapping.smooth_frames`` or ``mapping.refit_frames``
    off); None when it ran, and for runs older than this key."""
    version: str | None = None
    """The vtdslam package version that produced the run (``formats.version``); None for older runs."""
    commit: str | None = None
    """The git commit (40 hex digits) of the checkout that produced the run; None outside a git checkout."""
    stages: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Each stage's summary by stage name (``culling``, ``restoration``), a stage's own shape; with truth a
    ``truth`` entry (see :meth:`truth_scores`)."""
    ate: ErrorStats | None = None
    """Absolute trajectory error after SE(3) alignment, metres, against the raw ground truth (the published
    convention: for Bonn the marker's poses, see :attr:`ate_against`); None without ground truth."""
    matched_poses: int | None = None
    """Poses associated with ground truth for the ATE."""
    rpe: RpeMetrics | None = None
    """Drift per second (``delta_s``) against the camera's ground truth (a marker's corrected to it, see
    :attr:`rpe_against`); None without ground truth or on too short a run. Runs made before the ground-truth
    frame existed scored it against the raw ground truth (:attr:`rpe_against` absent)."""
    groundtruth_frame: str | None = None
    """What the sequence's ground truth is the pose of (``formats.catalog.GROUNDTRUTH_FRAMES``: ``camera`` or
    ``bonn-marker``); None in runs made before it was recorded."""
    ate_against: str | None = None
    """What :attr:`ate` was measured against (``camera``, or e.g. ``bonn-marker (raw ground truth, published
    convention)``)."""
    ate_corrected: ErrorStats | None = None
    """ATE against the camera's ground truth, metres (equal to :attr:`ate` when the ground truth is the camera's)."""
    ate_corrected_against: str | None = None
    """What :attr:`ate_corrected` was measured against (``camera``, ``camera (corrected from bonn-marker)``)."""
    rpe_against: str | None = None
    """What :attr:`rpe` and :attr:`rpe_frame` were measured against."""
    rpe_frame: RpeMetrics | None = None
    """Drift per frame: RPE over consecutive estimate poses (``delta_frames`` 1), against the camera's truth."""
    evaluation_error: str | None = None
    """Why ATE and RPE are absent although the sequence has ground truth."""
    extra: dict[str, Any] = field(default_factory=dict)
    """Top-level keys this schema does not know (non-mapping values), kept as they are."""

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RunMetrics:
        """A metrics.json blob; absent or malformed entries are None (or empty), old RPE spellings are read."""
        d = d if isinstance(d, Mapping) else {}
        known = {*_CORE, *_PROVENANCE, *_EVALUATION}
        stages = {k: dict(v) for k, v in d.items() if k not in known and isinstance(v, Mapping)}
        extra = {k: v for k, v in d.items() if k not in known and k not in stages}
        err, preset = d.get("evaluation_error"), d.get("preset")
        version, commit = d.get("version"), d.get("commit")
        overlapped = d.get("overlapped_stages")
        return cls(
            **{k: _count(d.get(k)) for k in _COUNTS},
            fps=number(d.get("fps")), tracking_fps=number(d.get("tracking_fps")),
            tracking_cpu_ms=number(d.get("tracking_cpu_ms")), timings_ms=_dict(d.get("timings_ms")) or {},
            overlapped_stages=list(overlapped) if isinstance(overlapped, list | tuple) else [],
            dense_points=_count(d.get("dense_points")), stage_info=_dict(d.get("stage_info")) or {},
            peak_rss_mb=number(d.get("peak_rss_mb")), camera=_dict(d.get("camera")) or {},
            preset=preset if isinstance(preset, str) else None, start=_count(d.get("start")),
            tracked_fraction=number(d.get("tracked_fraction")), warnings=_strings(d.get("warnings")),
            smoothing_skipped=_string(d.get("smoothing_skipped")),
            version=version if isinstance(version, str) else None, commit=commit if isinstance(commit, str) else None,
            stages=stages,
            ate=ErrorStats.from_dict(d.get("ate")), matched_poses=_count(d.get("matched_poses")),
            rpe=RpeMetrics.from_dict(d.get("rpe")),
            groundtruth_frame=_string(d.get("groundtruth_frame")), ate_against=_string(d.get("ate_against")),
            ate_corrected_against=_string(d.get("ate_corrected_against")), rpe_against=_string(d.get("rpe_against")),
            ate_corrected=ErrorStats.from_dict(d.get("ate_corrected")),
            rpe_frame=RpeMetrics.from_dict(d.get("rpe_frame")),
            evaluation_error=err if isinstance(err, str) else None, extra=extra,
        )

    def to_dict(self) -> dict[str, Any]:
        """The metrics.json shape (see the class docstring for the order)."""
        out: dict[str, Any] = {k: getattr(self, k) for k in _CORE}
        if self.version is not None or self.commit is not None:  # both keys; the commit null outside a checkout
            out.update({k: getattr(self, k) for k in _PROVENANCE})
        out.update(self.stages)
        if self.ate is not None:
            out["ate"] = self.ate.to_dict()
        if self.matched_poses is not None:
            out["matched_poses"] = self.matched_poses
        if self.rpe is not None:
            out["rpe"] = self.rpe.to_dict()
        for key in _LABELS:
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.ate_corrected is not None:
            out["ate_corrected"] = self.ate_corrected.to_dict()
        if self.rpe_frame is not None:
            out["rpe_frame"] = self.rpe_frame.to_dict()
        if self.evaluation_error is not None:
            out["evaluation_error"] = self.evaluation_error
        out.update(self.extra)
        return out

    def truth_scores(self) -> TruthScores:
        """The culling stage's mask and feature scores and the restoration stage's PSNR (finite or None)."""
        culling = _dict(self.stages.get("culling", {}).get("truth")) or {}
        restoration = _dict(self.stages.get("restoration", {}).get("truth")) or {}
        return TruthScores(finite(culling.get("mask_iou")), finite(culling.get("feature_precision")),
                           finite(culling.get("feature_recall")), finite(restoration.get("restoration_psnr")))


def with_current_spelling(blob: Mapping[str, Any]) -> dict[str, Any]:
    """``blob`` with every key kept as it is, plus an old-spelled ``rpe``'s figures under today's names
    (``rpe.trans``, ``rpe.rot_deg``), so the api's clients read one spelling; a current blob comes back equal."""
    out = dict(blob)
    old, rpe = blob.get("rpe"), RpeMetrics.from_dict(blob.get("rpe"))
    if isinstance(old, Mapping) and rpe is not None:
        now = {"trans": rpe.trans.to_dict(), "rot_deg": rpe.rot_deg.to_dict()}
        out["rpe"] = {**old, **{k: v for k, v in now.items() if not isinstance(old.get(k), Mapping)}}
    return out


def format_run_metrics(metrics: RunMetrics) -> str:
    """The text of a metrics.json (JSON, 2-space indent; NaN written as NaN, as json.dumps does)."""
    return json.dumps(metrics.to_dict(), indent=2)


def write_run_metrics(path: Path, metrics: RunMetrics) -> None:
    """:func:`format_run_metrics` into ``path``."""
    path.write_text(format_run_metrics(metrics))


def read_run_metrics(path: Path) -> RunMetrics:
    """A metrics.json file (NaN accepted, as json.loads does); FormatError when it is not a JSON object."""
    try:
        blob = json.loads(path.read_text(encoding="utf-8", errors="replace"))
    except json.JSONDecodeError as exc:
        raise FormatError(f"not JSON ({exc.msg})", path=path, line=exc.lineno) from None
    if not isinstance(blob, dict):
        raise FormatError("not a JSON object", path=path)
    return RunMetrics.from_dict(blob)
