"""One run: per-frame stages -> tracking -> local mapping -> loop closure per `step`, then in `finish` global BA,
frame refit, the dense map, metrics and evaluation.

The per-frame state kept is the pose relative to its reference keyframe, so BA and loop corrections move every
frame's pose at the end, and (`mapping.refit_frames`) the map points it matched, so each frame's pose is then
re-solved against the final map (`mapping/frame_refit.py`) and (`mapping.smooth_frames`) all frames smoothed
together under a motion prior (`mapping/smoothing.py`). Before each frame the stages get a fresh
`StageContext` (the motion model's predicted pose, the last tracked pose and its covariance, the run's history of
past frames), never the tracker. The run owns that history (`worker.slam.history`): it records each frame after
its stages ran and gives it its pose once tracked. With the sequence's truth, an observer scores the stages'
outputs against it (`truth_observer`); its scores are the "truth" entries of the stages' metrics.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import replace
from types import TracebackType

import numpy as np

from formats.class_palette import class_overlay
from worker.slam.camera import Camera
from worker.slam.config import PipelineConfig
from worker.slam.errors import TrackingFailed
from worker.slam.geometry.se3 import orthonormalize
from worker.slam.history import FrameHistory, PastFrame
from worker.slam.io.prepare_ahead import Prepared
from worker.slam.io.sequence import Frame, Sequence
from worker.slam.io.trajectory import Trajectory
from worker.slam.mapping.carve import FrameViews
from worker.slam.mapping.dense_map import build_dense_map
from worker.slam.mapping.frame_refit import refit_poses
from worker.slam.mapping.smoothing import SmootherSettings, smooth_poses
from worker.slam.run.callbacks import ProgressFn
from worker.slam.run.deferred import DeferredWork
from worker.slam.run.evaluation import RunEvaluation, evaluate_run
from worker.slam.run.frame_log import FrameLog
from worker.slam.run.metrics import run_metrics, smoothing_skipped, with_truth
from worker.slam.run.parts import SlamParts, build_slam
from worker.slam.run.previews import PreviewPicker
from worker.slam.run.result import RunResult
from worker.slam.run.stage_runner import StageRunner
from worker.slam.run.timer import StageTimer
from worker.slam.run.truth_observer import TruthObserver
from worker.slam.stages import FrameInputs, FrameStage, StageContext, TrackedPose
from worker.slam.tracking.result import TrackResult
from worker.slam.truth import Truth

log = logging.getLogger(__name__)

StepFn = Callable[["PipelineRun", Frame, FrameInputs, TrackResult], None]
"""Called after each frame's step with the run, the frame, what its stages made of it and its tracking result
(the service writes partial snapshots through it while a job runs); it must not change the run."""


class PipelineRun:
    """Contract: `step(frame)` once per frame, in frame order, on one thread (the pipeline thread); then
    `finish()` once, on the same thread, for the result. Use it as a context manager (or call `close()`): leaving
    stops the background thread that runs deferred stage work, also after an error.

    `sequence` (optional) is what the stages may read neighbouring frames from, and its ground truth scores the
    trajectory; `start` and `total` (the first frame's index and the number of frames the caller will step)
    place the previews and count progress.
    """

    def __init__(self, camera: Camera, config: PipelineConfig, stages: list[FrameStage], *,
                 sequence: Sequence | None = None, truth: Truth | None = None, start: int = 0, total: int = 0,
                 progress: ProgressFn | None = None, restore_behind: bool = True,
                 on_step: StepFn | None = None) -> None:
        """`restore_behind`: run deferred stage work (restoration of keyframes and previews) on a background
        thread while the next frames are tracked (False: on this thread, right after the frame's tracking).
        `on_step`: see `StepFn`."""
        self.camera, self.config, self.sequence = camera, config, sequence
        self.on_step = on_step
        self.start, self.total, self.progress = start, total, progress
        self.parts: SlamParts = build_slam(camera, config)
        self.timer = StageTimer()
        self.stages = StageRunner(stages, self.timer)
        self.previews = PreviewPicker(start, total)
        self.history = FrameHistory(self.stages.history_frames())
        self.observer = TruthObserver(truth) if truth is not None else None
        self.deferred = DeferredWork(restore_behind, self.previews, config.dense.stride, self.history,
                                     self.observer.restored if self.observer is not None else None)
        self.log = FrameLog(config.mapping.refit_frames)
        dense = config.dense
        self.carve_frames = FrameViews(dense.carve_every if dense.enabled and dense.carve else 0, dense.stride,
                                       dense.carve_max_views)
        self._ctx = StageContext(camera, config, sequence, truth)
        self._t_loop = time.perf_counter()

    def __enter__(self) -> PipelineRun:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        self.deferred.close()

    # ---- per frame ---------------------------------------------------------------------------------------

    def step(self, frame: Frame | Prepared) -> TrackResult:
        """Run the stages on one frame, track it, map its keyframe; a `Prepared` frame brings the stages'
        `prepare` results computed ahead (`io.prepare_ahead`), a plain `Frame` has them computed here."""
        item = frame if isinstance(frame, Prepared) else Prepared(frame)
        self.timer.mark()
        inputs, deferred_by = self.stages.process(item, self._frame_context())
        self._record(item.frame, inputs)
        res = self._track(item.frame, inputs)
        self.log.add_stage_info(inputs.info)
        self._offer_previews(item.frame, inputs)
        if res.keyframe is not None:
            self._map(res)
        k = len(self.log)
        row = self.log.add(item.frame.timestamp, res, inputs.info, self.parts.map)
        self.carve_frames.offer(k, item.frame.depth)
        if inputs.deferred is not None and deferred_by is not None:
            self.deferred.offer(inputs, res, self.timer.ms[deferred_by], row, self.log.stage_info)
        self.deferred.release(item.frame.index)  # its later frames have gone through the stages
        if self.progress is not None:
            self.progress(k + 1, self.total, "tracking")
        if self.on_step is not None:
            self.on_step(self, item.frame, inputs, res)
        return res

    def _offer_previews(self, frame: Frame, inputs: FrameInputs) -> None:
        """The stages' previews of `frame`, with the frame coloured by its segmentation classes when a preview of it
        is due (attached to the previews its deferred work brings later, if it has some)."""
        labels = inputs.class_labels
        extra: dict[str, np.ndarray] = {}
        if labels is not None and self.previews.wants(frame.index):
            extra = {"rgb": frame.rgb, "classes": class_overlay(frame.rgb, labels.labels, labels.classes,
                                                                labels.dynamic_classes, inputs.dynamic_mask)}
        if inputs.previews or (extra and inputs.deferred is None):
            self.previews.offer(frame.index, {**extra, **(inputs.previews or {})})
        elif extra:
            self.previews.attach(frame.index, extra)

    def _frame_context(self) -> StageContext:
        """The run's context with the tracker's prediction for the coming frame, its last tracked pose and the
        history, whose record of that frame gets its pose now (a lost frame's stays None)."""
        tracker = self.parts.tracker
        last = tracker.last_result
        if last is not None:
            self.history.set_pose(last.index, last.T_WC)
        return replace(self._ctx, T_WC_pred=tracker.predicted_pose(), history=self.history.view(),
                       last=None if last is None else TrackedPose(last.index, last.T_WC, last.covariance))

    def _record(self, frame: Frame, inputs: FrameInputs) -> None:
        """Keep what the stages made of `frame` in the history; show it to the observer (whose truth reads count
        in no lap of the timer: not in the tracking that follows)."""
        if self.history.length:
            self.history.append(PastFrame(frame.index, frame.timestamp, frame.rgb, frame.depth, inputs.extracted,
                                          inputs.features, inputs.potentially_dynamic, inputs.dynamic_mask))
        if self.observer is not None:
            self.observer.frame(frame.index, inputs)
            self.timer.mark()

    def _track(self, frame: Frame, inputs: FrameInputs) -> TrackResult:
        c0 = time.process_time()
        res = self.parts.tracker.track(frame.index, frame.timestamp, frame.rgb, frame.depth, inputs.track_inputs())
        self.log.cpu_tracking.append(time.process_time() - c0)
        self.timer.lap("tracking")
        return res

    def _map(self, res: TrackResult) -> None:
        """Local mapping and loop closure on the new keyframe of `res`."""
        assert res.keyframe is not None
        self.parts.mapper.process(res.keyframe)
        self.timer.lap("local_mapping")
        if self.parts.closer is not None:
            self.parts.closer.process(res.keyframe)
            self.timer.lap("loop_closure")
        self.parts.tracker.on_map_updated(res)

    # ---- at the end --------------------------------------------------------------------------------------

    def finish(self) -> RunResult:
        """Complete the deferred work, then global BA, frame refit, the dense map, metrics and evaluation.
        Raises `TrackingFailed` (saying why) when no frame was tracked; the result's trajectory holds only the
        tracked frames (TUM tools expect estimated poses only), the per-frame records all of them."""
        self.deferred.finish()  # the keyframes' restored images and the previews, before the dense map
        loop_s = time.perf_counter() - self._t_loop
        self.close()
        tracked = np.array(self.log.tracked, dtype=bool)
        if not tracked.any():
            raise TrackingFailed(self._why_nothing_tracked(),
                                 detail={"frames": len(self.log), "most_features": self.log.most_features,
                                         "most_features_with_depth": self.log.most_with_depth})
        smap = self.parts.map
        if self.config.mapping.final_global_ba:
            self.timer.mark()
            self.parts.mapper.global_bundle_adjust(self.config.mapping.global_ba_iterations)
            self.timer.lap("global_ba")
        self._progress("dense")
        every, n_refit, n_smoothed, smoothing_skip = self._trajectory()
        traj = Trajectory(every.timestamps[tracked], every.poses[tracked])  # no pose for a frame never tracked
        kf_traj = Trajectory(np.array([kf.timestamp for kf in smap.keyframes]), smap.poses())
        cloud = self._dense_map(every, tracked)
        metrics = run_metrics(self.log, self.parts, self.timer, loop_s=loop_s, frames_refit=n_refit,
                              frames_smoothed=n_smoothed, smoothing_skipped=smoothing_skip,
                              overlapped=self.stages.overlapped, dense_points=int(len(cloud[0])) if cloud else 0,
                              camera=self.camera, preset=self.config.name, start=self.start)
        truth = self.observer.summaries(self.stages.names()) if self.observer is not None else {}
        metrics.update(with_truth(self.stages.summaries(), truth))
        ev = RunEvaluation({})
        groundtruth = self.sequence.groundtruth if self.sequence is not None else None
        if groundtruth is not None:
            self._progress("evaluation")
            ev = evaluate_run(groundtruth, traj, self.config.eval, self.camera.groundtruth_frame)
            metrics.update(ev.metrics)
        rows = self.log.finished_rows(self.start, ev.ate_errors)
        return RunResult(traj, kf_traj, metrics, smap, tracked, cloud, rows, ev.aligned_groundtruth,
                         self.previews.kept)

    def _progress(self, stage: str) -> None:
        if self.progress is not None:
            self.progress(self.total, self.total, stage)

    def _why_nothing_tracked(self) -> str:
        """"no frame was tracked: ..." with the likeliest reason the log shows."""
        log, cam, fc = self.log, self.camera, self.config.features
        head = f"no frame was tracked: {len(log)} frames of {cam.width}x{cam.height}"
        if log.most_features == 0:
            return (f"{head}, and no frame had any ORB feature (images too small or without texture; "
                    f"{fc.n_levels} pyramid levels need images of at least about 64x48 pixels)")
        if log.most_with_depth == 0:
            return (f"{head}, and no feature had a valid depth (depth images all zero, or every depth outside "
                    f"{fc.min_depth_m:g}..{fc.max_depth_m:g} m: a wrong depth scale?)")
        return (f"{head}: at most {log.most_with_depth} features with a valid depth in a frame, too few to start "
                f"a map (tracking.init_min_points {self.config.tracking.init_min_points})")

    def _trajectory(self) -> tuple[Trajectory, int, int, str | None]:
        """Every frame's final T_WC, lost ones too (through its reference keyframe, re-solved against the final map
        when `mapping.refit_frames`, then smoothed when `mapping.smooth_frames`), how many frames were re-solved,
        how many the smoothing moved and why it did not run (None when it ran). Starts the timer's lap of "dense"."""
        smap, mc = self.parts.map, self.config.mapping
        self.timer.mark()
        poses = self.log.poses(smap)
        n_refit = n_smoothed = 0
        skipped = smoothing_skipped(mc.smooth_frames, self.log.matches is not None, len(smap))
        if self.log.matches is not None and len(smap):
            n_refit, info = refit_poses(poses, self.log.matches, smap.points, self.parts.sensor, self.config.tracking)
            self.timer.lap("frame_refit")  # "dense" times the dense map alone
            if mc.smooth_frames:
                settings = SmootherSettings(mc.smooth_accel_sigma, mc.smooth_angular_sigma)
                smoothed = smooth_poses(poses, np.asarray(self.log.stamps, dtype=np.float64), info, settings)
                n_smoothed = int(np.any(smoothed != poses, axis=(1, 2)).sum())
                poses = smoothed
                self.timer.lap("frame_smoothing")
        if skipped is not None:
            log.info("frame smoothing skipped: %s", skipped)
        traj = Trajectory(np.array(self.log.stamps, dtype=np.float64), orthonormalize(poses))
        return traj, n_refit, n_smoothed, skipped

    def _dense_map(self, traj: Trajectory, tracked: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The dense map (M,3) float32 xyz, (M,3) uint8 RGB of the keyframes at their final poses."""
        smap, dense = self.parts.map, self.config.dense
        if not (dense.enabled and len(smap)):
            return None
        carve_views = self.carve_frames.views(traj.poses, tracked) if self.carve_frames.every else None
        cloud = build_dense_map(smap.keyframes, self.parts.sensor.K, self.parts.sensor.dist, dense, carve_views)
        self.timer.lap("dense")
        return cloud
