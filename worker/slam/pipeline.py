"""Run a sequence through the pipeline: per-frame stages -> tracking -> local mapping -> loop closure -> dense map.

Frames are streamed (read one at a time); the per-frame state kept is the pose relative to its reference
keyframe, so BA and loop corrections move every frame's pose at the end, and (`mapping.refit_frames`) the map
points it matched, so each frame's pose is then re-solved against the final map (`mapping/frame_refit.py`).

Per-frame stages (segmentation, dynamic culling, restoration) follow the contract of `worker.slam.stages`; a
config lists the stages it runs in `config.stages`. Before each frame the pipeline gives them a fresh
`StageContext` (the motion model's predicted pose, the last tracked pose and its covariance), never the tracker.

Overlap: frames are decoded ahead on a background thread (`read_ahead`), and stages' `prepare(frame)` (the
segmentation network) run ahead on another (`prepare_ahead`), so frame k+1 is segmented while frame k is culled
and tracked. Results are the same either way. `timings_ms[stage]` stays the stage's compute time per frame
(wherever it ran); `timings_ms[stage + '_wait']` is what the pipeline thread waited for the prepared result, and
`metrics['overlapped_stages']` names the stages that ran ahead.

Deferred work: a stage whose output tracking does not read may leave it in `FrameInputs.deferred` (restoration
on demand); it runs after tracking only when the frame became a keyframe or a preview is due, and not before
`FrameInputs.deferred_delay` later frames went through the stages (restoration takes them for references), on a
background thread behind the pipeline thread (`restore_behind`; its results are stored in frame order, the same
as in line), and its time is added to the stage's own entry for that frame.
"""
from __future__ import annotations

import json
import resource
import time
from collections import defaultdict, deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from itertools import chain
from pathlib import Path

import cv2
import numpy as np

from formats import artifacts
from formats.frame_stats import write_frame_stats
from formats.ply import write_ply
from formats.run_metrics import RunMetrics, write_run_metrics
from worker.slam.catalog import shipped_catalog
from worker.slam.config import PipelineConfig
from worker.slam.errors import ConfigError, EvaluationError, SlamError
from worker.slam.geometry.se3 import inv, orthonormalize
from worker.slam.io.prepare_ahead import PrepareAhead, Prepared
from worker.slam.io.read_ahead import ReadAhead
from worker.slam.io.sequence import Frame, Sequence
from worker.slam.io.trajectory import Trajectory, write_tum_trajectory
from worker.slam.io.work_behind import WorkBehind
from worker.slam.map.map import Map
from worker.slam.mapping.carve import FrameViews
from worker.slam.mapping.dense_map import build_dense_map
from worker.slam.mapping.frame_refit import FrameMatchLog, refit_poses
from worker.slam.mapping.local_mapping import LocalMapper
from worker.slam.mapping.loop_closure import LoopCloser
from worker.slam.stages import FrameInputs, FrameStage, StageContext, TrackedPose
from worker.slam.tracking.result import TrackResult
from worker.slam.tracking.tracker import Tracker
from worker.slam.truth import load_truth

ProgressFn = Callable[[int, int, str], None]
"""(frames_done, frames_total, stage) -- stage is 'tracking', 'dense', 'evaluation' or 'writing'."""
CancelFn = Callable[[], bool]
"""Returns True when the job should stop; checked before every frame."""


class PipelineCancelled(SlamError):
    """The run was stopped by its cancellation check."""

    code = "cancelled"


@dataclass
class RunResult:
    trajectory: Trajectory
    """Every processed frame's T_WC."""
    keyframes: Trajectory
    metrics: dict
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


class _Timer:
    def __init__(self) -> None:
        self.ms: dict[str, list[float]] = defaultdict(list)

    def __call__(self, name: str, t0: float, extra_ms: float = 0.0) -> float:
        """Record the time since `t0` (plus `extra_ms` spent elsewhere, e.g. on another thread) under `name`."""
        t1 = time.perf_counter()
        self.ms[name].append((t1 - t0) * 1000 + extra_ms)
        return t1

    def means(self) -> dict[str, float]:
        return {k: round(float(np.mean(v)), 3) for k, v in self.ms.items()}


def run_pipeline(sequence: Sequence, config: PipelineConfig, out_dir: Path | str | None = None, *,
                 start: int = 0, max_frames: int | None = None, progress: ProgressFn | None = None,
                 should_cancel: CancelFn | None = None, stages: list[FrameStage] | None = None,
                 read_ahead: int = 2, prepare_ahead: bool = True, restore_behind: bool = True) -> RunResult:
    """Track frames [start, start+max_frames) of `sequence`; write the outputs to `out_dir` when given.

    `read_ahead`: frames decoded ahead on a background thread (0: read on this thread).
    `prepare_ahead`: with read-ahead, run the stages' `prepare(frame)` on another background thread as frames
    are decoded (False, or `read_ahead` 0: each stage computes it in `process` on this thread).
    `restore_behind`: run deferred stage work (restoration of keyframes and previews) on a background thread
    while the next frames are tracked (False: on this thread, right after the frame's tracking).
    """
    if start < 0 or start >= len(sequence):
        raise ConfigError(f"start {start} is outside the sequence (0..{len(sequence) - 1})")
    stop = len(sequence) if max_frames is None else min(len(sequence), start + max(0, max_frames))
    total = stop - start
    first = sequence[start]  # also fixes the camera size (Sequence rescales it on first read)
    camera = sequence.camera
    stages = shipped_catalog().build_stages(config, camera) if stages is None else stages
    tracker = Tracker(camera, config)
    smap = tracker.map
    mapper = LocalMapper(smap, config.mapping, camera.K, tracker.bf, tracker.extractor.inv_sigma2,
                         config.tracking.huber_px, (camera.width, camera.height))
    closer = (LoopCloser(smap, config.loop, camera.K, tracker.bf, tracker.extractor.inv_sigma2)
              if config.loop.enabled else None)
    run_ctx = StageContext(camera, config, sequence, load_truth(sequence.root))
    previews = _PreviewPicker(start, total)
    timer = _Timer()
    rel: list[tuple[int, np.ndarray]] = []  # per frame: (reference keyframe, T_ref_frame)
    matches = FrameMatchLog() if config.mapping.refit_frames else None
    stamps, tracked = np.zeros(total), np.zeros(total, bool)
    n_reloc = n_new_maps = n_merges = 0
    frame_info: list[dict] = []
    stage_info: dict[str, list[float]] = defaultdict(list)
    cpu_tracking: list[float] = []  # CPU seconds (all threads): comparable when the machine is shared
    overlapped: set[str] = set()  # stages whose work ran ahead on another thread
    dense = config.dense
    carve_frames = FrameViews(dense.carve_every if dense.enabled and dense.carve else 0, dense.stride,
                              dense.carve_max_views)
    t_loop = time.perf_counter()
    # frames after the first are decoded on a background thread while this one runs the stages; the reader
    # queues each decoded frame's `prepare` work on a second thread (left by `with` before the reader stops)
    with PrepareAhead(_preparers(stages) if prepare_ahead and read_ahead > 0 else {}) as prep, \
            ReadAhead(lambda i: prep.submit(sequence[i]), range(start + 1, stop), read_ahead) as ahead, \
            WorkBehind(restore_behind) as behind:
        waiting: deque[_Deferred] = deque()  # deferred work that waits for later frames, by when it may start
        frames: Iterator[Prepared] = chain([prep.submit(first)], ahead)
        for k in range(total):
            if should_cancel is not None and should_cancel():
                raise PipelineCancelled(f"cancelled after {k} of {total} frames")
            t = time.perf_counter()
            item = next(frames)  # with read-ahead: the wait for the reader thread, not the decoding
            frame = item.frame
            t = timer("read", t)
            inputs = FrameInputs()
            ctx = _frame_context(run_ctx, tracker)
            deferred_by = None  # the stage that left work for after tracking
            for st in stages:
                ahead_ms = 0.0
                pending = item.pending.get(st.name)
                if pending is not None:
                    inputs.prepared[st.name], ahead_ms = pending.result()  # a prepare error is raised here
                    if inputs.prepared[st.name] is not None:  # None: nothing to do ahead (e.g. truth masks)
                        overlapped.add(st.name)
                    t = timer(f"{st.name}_wait", t)
                inputs = st.process(frame, inputs, ctx)
                t = timer(st.name, t, ahead_ms)
                if inputs.deferred is not None and deferred_by is None:
                    deferred_by = st.name
            c0 = time.process_time()
            res = tracker.track(frame.index, frame.timestamp, frame.rgb, frame.depth, inputs.track_inputs())
            cpu_tracking.append(time.process_time() - c0)
            t = timer("tracking", t)
            for key, val in _numbers(inputs.info).items():
                stage_info[key].append(val)
            if inputs.previews:
                previews.offer(frame.index, inputs.previews)
            if res.keyframe is not None:
                mapper.process(res.keyframe)
                t = timer("local_mapping", t)
                if closer is not None:
                    closer.process(res.keyframe)
                    t = timer("loop_closure", t)
                tracker.on_map_updated(res)
            stamps[k], tracked[k] = frame.timestamp, res.ok
            carve_frames.offer(k, frame.depth)
            row = {"features": len(res.feats), "matched_points": int(np.sum(res.point_ids >= 0)),
                   **{k2: v for k2, v in inputs.info.items() if isinstance(v, (int, float))}}
            frame_info.append(row)
            if inputs.deferred is not None and deferred_by is not None:
                _defer(waiting, inputs, res, previews, config.dense.stride, timer.ms[deferred_by], row, stage_info)
            while waiting and waiting[0][0] <= frame.index:  # their later frames have gone through the stages
                behind.submit(*waiting.popleft()[1:])
            behind.collect()
            n_reloc += int(res.relocalised)
            n_new_maps += int(res.new_map)
            n_merges += int(res.merged)
            rel.append(_relative(smap, res))
            if matches is not None:
                matches.add(res.point_ids, res.feats.uv, res.feats.depth, res.feats.octave,
                            res.ok and res.keyframe is None)
            if progress is not None:
                progress(k + 1, total, "tracking")
        while waiting:  # the last frames' deferred work: the frames it waited for do not exist
            behind.submit(*waiting.popleft()[1:])
        behind.finish()  # the keyframes' restored images and the previews, before the dense map
    loop_s = time.perf_counter() - t_loop
    if config.mapping.final_global_ba:
        t = time.perf_counter()
        mapper.global_bundle_adjust(config.mapping.global_ba_iterations)
        timer("global_ba", t)

    if progress is not None:
        progress(total, total, "dense")
    t = time.perf_counter()
    poses = np.stack([smap.keyframes[r].T_WC @ T_rf if len(smap) else T_rf for r, T_rf in rel])
    n_refit = 0
    if matches is not None and len(smap):
        n_refit = refit_poses(poses, matches, smap.points, camera.K, tracker.bf, tracker.extractor.inv_sigma2,
                              config.tracking)
        t = timer("frame_refit", t)  # "dense" below times the dense map alone
    traj = Trajectory(stamps, orthonormalize(poses))
    kf_traj = Trajectory(np.array([kf.timestamp for kf in smap.keyframes]), smap.poses())
    cloud = None
    if config.dense.enabled and len(smap):
        cloud = build_dense_map(smap.keyframes, camera.K,
                                np.asarray(camera.dist) if camera.has_distortion else None, config.dense,
                                carve_frames.views(traj.poses, tracked) if carve_frames.every else None)
        timer("dense", t)
    metrics = {
        "frames": total, "tracked": int(tracked.sum()), "lost": int((~tracked).sum()),
        "relocalisations": n_reloc, "new_maps": n_new_maps, "map_merges": n_merges,
        "established_switches": tracker.established_switches,
        "rescued_frames": tracker.rescued_frames, "last_pose_retries": tracker.last_pose_retries,
        "frames_refit": n_refit,
        "keyframes": len(smap), "map_points": smap.points.n_alive, "fused_observations": mapper.fused,
        "loops": closer.n_loops if closer else 0, "loops_applied": closer.n_applied if closer else 0,
        "fps": round(total / loop_s, 2) if loop_s > 0 else None,
        "tracking_fps": round(1000.0 / np.mean(timer.ms["tracking"]), 2) if timer.ms["tracking"] else None,
        "tracking_cpu_ms": round(1000 * float(np.mean(cpu_tracking)), 3) if cpu_tracking else None,
        "timings_ms": timer.means(),
        "overlapped_stages": sorted(overlapped),
        "dense_points": int(len(cloud[0])) if cloud else 0,
        "stage_info": {k: round(float(np.mean(v)), 4) for k, v in stage_info.items()},
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "camera": camera.to_dict(), "preset": config.name, "start": start,
    }
    for st in stages:
        summary = getattr(st, "summary", None)
        if summary is not None:
            metrics[st.name] = summary()
    aligned_gt, ate_errors = None, None
    if sequence.groundtruth is not None:
        if progress is not None:
            progress(total, total, "evaluation")
        ev, aligned_gt, ate_errors = _evaluate(sequence.groundtruth, traj, config)
        metrics.update(ev)
    for k, info in enumerate(frame_info):
        info.update(frame_index=start + k, timestamp=float(stamps[k]), tracked=bool(tracked[k]),
                    ate_error=None if ate_errors is None else ate_errors.get(round(float(stamps[k]), 6)))
    result = RunResult(traj, kf_traj, metrics, smap, tracked, cloud, frame_info, aligned_gt, previews.kept)
    if out_dir is not None:
        if progress is not None:
            progress(total, total, "writing")
        write_outputs(result, config, Path(out_dir))
    return result


_Deferred = tuple[int, Callable[[], float], Callable[[float], None]]
"""(frame index after whose stages the work may start, work, done), for `WorkBehind.submit`."""


def _defer(waiting: deque[_Deferred], inputs: FrameInputs, res: TrackResult, previews: _PreviewPicker,
           stride: int, stage_ms: list[float], row: dict, stage_info: dict[str, list[float]]) -> None:
    """Queue in `waiting` the work a stage deferred (restoration) when this frame became a keyframe or a preview
    is due (dropped otherwise: it holds the frame's images), to start `inputs.deferred_delay` frames later. When
    it is done: the keyframe gets the restored images the tracker would have stored had they been there when it
    tracked, the previews their slot (claimed now, in frame order, as if they had been offered now), the frame's
    figures its `row` and `stage_info`, and its time the stage's entry for this frame."""
    deferred, inputs.deferred = inputs.deferred, None
    why = "keyframe" if res.keyframe is not None else "preview" if previews.wants(res.index) else None
    if deferred is None or why is None:
        return
    keep_previews = previews.claim(res.index)
    out = FrameInputs(features=inputs.features)  # written by the background thread only
    entry = len(stage_ms) - 1

    def work() -> float:
        t0 = time.perf_counter()
        deferred(out, why)
        return (time.perf_counter() - t0) * 1000

    def done(ms: float) -> None:
        stage_ms[entry] += ms
        if res.keyframe is not None and out.restored_rgb is not None and out.restored_depth is not None:
            res.keyframe.set_dense_images(out.restored_rgb, out.restored_depth, stride)
        if keep_previews and out.previews:
            previews.kept[res.index] = out.previews
        for key, val in _numbers(out.info).items():
            stage_info[key].append(val)
            row[key] = out.info[key]

    waiting.append((res.index + inputs.deferred_delay, work, done))


def _numbers(info: dict) -> dict[str, float]:
    """The numeric entries of a frame's `info` (flags left out), as floats."""
    return {k: float(v) for k, v in info.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def _preparers(stages: list[FrameStage]) -> dict[str, Callable[[Frame], object]]:
    """The stages' `prepare(frame)` functions (optional in the stage contract), by stage name."""
    out: dict[str, Callable[[Frame], object]] = {}
    for st in stages:
        prepare = getattr(st, "prepare", None)
        if callable(prepare):
            out[st.name] = prepare
    return out


def _frame_context(run_ctx: StageContext, tracker: Tracker) -> StageContext:
    """The run's context with the tracker's prediction for the coming frame and its last tracked pose."""
    last = tracker.last_result
    return replace(run_ctx, T_WC_pred=tracker.predicted_pose(),
                   last=None if last is None else TrackedPose(last.index, last.T_WC, last.covariance))


def _relative(smap: Map, res: TrackResult) -> tuple[int, np.ndarray]:
    if not len(smap):
        return 0, res.T_WC.copy()
    ref = min(res.ref_kf, len(smap) - 1)
    return ref, inv(smap.keyframes[ref].T_WC) @ res.T_WC


def _evaluate(groundtruth: Trajectory, traj: Trajectory,
              config: PipelineConfig) -> tuple[dict, Trajectory | None, dict[float, float] | None]:
    """(metrics, ground truth aligned onto the estimate, per-frame ATE by rounded timestamp)."""
    from worker.slam.evaluation.metrics import evaluate

    try:
        ev = evaluate(groundtruth, traj, config.eval.max_diff_s, config.eval.rpe_delta_s)
    except EvaluationError as exc:
        return {"evaluation_error": exc.message}, None, None
    errors = {round(float(t), 6): float(e) for t, e in zip(ev.matched_timestamps, ev.ate_errors)}
    return ev.to_dict(), ev.aligned_groundtruth, errors


class _PreviewPicker:
    """Keeps the preview images of a few frames spread over the run (bounded memory)."""

    def __init__(self, start: int, total: int, count: int = 6) -> None:
        step = max(1, total // (count + 1))
        self.wanted = {start + step * (i + 1) for i in range(count)}
        self.kept: dict[int, dict[str, np.ndarray]] = {}

    def wants(self, index: int) -> bool:
        """Whether a frame with previews at `index` would be kept."""
        return any(w <= index for w in self.wanted)

    def claim(self, index: int) -> bool:
        """Whether the previews of frame `index` are kept: the first frame with previews at or after each wanted
        index (frames claim in order; the images may come later, into `kept`)."""
        due = [w for w in self.wanted if w <= index]
        self.wanted -= set(due)
        return bool(due)

    def offer(self, index: int, images: dict[str, np.ndarray]) -> None:
        if self.claim(index):
            self.kept[index] = images


def write_outputs(result: RunResult, config: PipelineConfig, out: Path) -> None:
    """trajectory.txt, keyframes.txt (TUM), map.ply, metrics.json, config.json."""
    out.mkdir(parents=True, exist_ok=True)
    write_tum_trajectory(out / artifacts.TRAJECTORY, result.trajectory, header="VTD-SLAM trajectory T_WC (every frame)")
    write_tum_trajectory(out / artifacts.KEYFRAMES, result.keyframes, header="VTD-SLAM keyframes T_WC")
    xyz, rgb = result.cloud if result.cloud is not None else (np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    write_ply(out / artifacts.MAP, xyz, rgb)
    write_run_metrics(out / artifacts.METRICS, RunMetrics.from_dict(result.metrics))
    (out / artifacts.CONFIG).write_text(json.dumps(config.to_dict(), indent=2))
    if result.aligned_groundtruth is not None:
        write_tum_trajectory(out / artifacts.GROUNDTRUTH_ALIGNED, result.aligned_groundtruth,
                             header="ground truth T_WC aligned onto the estimate (SE(3) Umeyama)")
    write_frame_stats(out / artifacts.FRAME_STATS, result.frame_stats)
    for index, images in result.previews.items():
        for kind, img in images.items():
            cv2.imwrite(str(out / artifacts.frame_image(index, kind)), cv2.cvtColor(img, cv2.COLOR_RGB2BGR),
                        [cv2.IMWRITE_JPEG_QUALITY, 85])

