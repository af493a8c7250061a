"""Partial results of a running job, written so the job page and the 3D viewer show
the run as it goes (names: ``formats.artifacts.PARTIALS``), in its folder of the artifact store.

:class:`PartialWriter` is the pipeline run's ``on_step`` hook (``worker.slam.run.pipeline_run.StepFn``). After
every frame it rewrites ``partial.json`` (the latest frames' index, timestamp, arrival, position, the counts: a
small file, how a live session's pose reaches the page; written on its own thread, newest first:
``worker.latest_file``); every ``interval_s`` it writes the trajectory and the
keyframes so far (TUM), the map so far (each keyframe's points back-projected once from its dense copy and moved
to the keyframe's current pose; the sparse map's points when the run keeps no dense copies) and the frame with
its masks, coloured by segmentation class (the classes and their colours in partial.json's `frame_legend`):
gathered on the pipeline thread, written on a writer thread. The files are removed when the job ends (its final
artifacts replace them).
"""
from __future__ import annotations

import json
import logging
import os
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from formats import artifacts
from formats.class_palette import class_overlay, legend, present_classes
from formats.ply import write_ply
from storage.artifacts import ArtifactStore
from worker.latest_file import LatestFile

if TYPE_CHECKING:
    from worker.slam.io.sequence import Frame
    from worker.slam.run.pipeline_run import PipelineRun
    from worker.slam.stages import ClassLabels, FrameInputs
    from worker.slam.tracking.result import TrackResult

log = logging.getLogger("worker.snapshots")


@dataclass
class SnapshotConfig:
    """How often and how much of a running job is written for the page and the viewer."""

    interval_s: float = 1.0
    """Trajectory, keyframes, map and frame images at most this often (partial.json after every frame)."""
    max_points: int = 150_000
    """The partial map is subsampled to at most this many points (the viewer redraws it each time)."""
    pixel_step: int = 2
    """Every n-th pixel of a keyframe's dense copy (itself every `dense.stride`-th pixel) enters the map."""
    recent: int = 64
    """Frames listed in partial.json (a client polling less often than the frames come still sees each)."""
    background: bool = True
    """Write the map, trajectory and images on a writer thread, and partial.json on another (newest first: a
    state superseded before it was written is skipped); False: all on the pipeline thread. Rewriting
    partial.json after every frame cost the pipeline thread 3.3 ms a frame of a 30 Hz live session on the loaded
    2-core VM (docs/results/realtime.md)."""


@dataclass
class _Cloud:
    """Keyframe points in the keyframe's camera frame: (N,3) float32 metres and (N,3) uint8 RGB."""

    xyz: np.ndarray
    rgb: np.ndarray


@dataclass
class _Snapshot:
    """What one snapshot writes, gathered on the pipeline thread (poses (4,4) T_WC; images (H,W,3) uint8 RGB and
    (H,W) bool masks, never written to by the run after their frame)."""

    frames: int
    stamps: list[float]
    poses: list[np.ndarray]
    kf_stamps: list[float]
    kf_poses: list[np.ndarray]
    clouds: list[tuple[_Cloud, np.ndarray]]
    sparse: np.ndarray | None
    rgb: np.ndarray
    potentially_dynamic: np.ndarray | None
    dynamic_mask: np.ndarray | None
    class_labels: ClassLabels | None = None


@dataclass
class PartialWriter:
    store: ArtifactStore
    job_id: str
    config: SnapshotConfig = field(default_factory=SnapshotConfig)
    counts: dict[str, int] = field(default_factory=dict)
    """Extra counts written to partial.json (a live session's frames received and dropped)."""

    def __post_init__(self) -> None:
        self.stamps: list[float] = []
        self.poses: list[np.ndarray] = []
        self.recent: deque[dict[str, Any]] = deque(maxlen=self.config.recent)
        self.arrivals: dict[int, float] = {}
        self.clouds: dict[int, _Cloud] = {}
        self.frames = self.tracked = self.map_points = 0
        self.last_full = 0.0
        self.spent_s = 0.0
        """Time the snapshots took on the pipeline thread (the job's timings_ms["snapshots"], per frame)."""
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="vtdslam-snapshots") if self.config.background else None
        self._pending: Future[None] | None = None
        self._state = (LatestFile(lambda data: self._put(artifacts.PARTIAL_STATE, data), self._failed,
                                  "vtdslam-partial-state") if self.config.background else None)
        self.error: str | None = None
        """Why snapshots stopped being written (the run goes on; the job's metrics name it as a warning)."""
        self.legend: list[dict[str, Any]] | None = None
        """The classes in the latest frame image and their colours (`formats.class_palette.legend`), once one was
        coloured by class; in partial.json as `frame_legend`."""

    def arrival(self, index: int, at: float) -> None:
        """When frame ``index`` reached the service (Unix seconds): reported beside its pose."""
        self.arrivals[index] = at

    def __call__(self, run: PipelineRun, frame: Frame, inputs: FrameInputs, res: TrackResult) -> None:
        """The run's ``on_step``: never fails the run (a snapshot that cannot be written is logged once)."""
        t0 = time.perf_counter()
        try:
            self._step(run, frame, inputs, res)
        except Exception as exc:  # noqa: BLE001 - snapshots are for watching; the run's results do not need them
            if self.error is None:
                self.error = f"partial results not written: {type(exc).__name__}: {exc}"
                log.warning("job %s: %s", self.job_id, self.error)
        finally:
            self.spent_s += time.perf_counter() - t0

    def _step(self, run: PipelineRun, frame: Frame, inputs: FrameInputs, res: TrackResult) -> None:
        self.frames += 1
        if res.ok:
            self.tracked += 1
            self.stamps.append(frame.timestamp)
            self.poses.append(res.T_WC.copy())
        self.recent.append({"index": frame.index, "timestamp": frame.timestamp,
                            "arrival": self.arrivals.pop(frame.index, None), "done": time.time(),
                            "tracked": bool(res.ok), "position": [round(float(v), 5) for v in res.T_WC[:3, 3]]})
        now = time.monotonic()
        if now - self.last_full >= self.config.interval_s:
            self.last_full = now
            self._write_full(run, frame, inputs)
        self.write_state(run_keyframes=len(run.parts.map))

    def write_state(self, **extra: Any) -> None:
        """partial.json, rewritten after every frame."""
        state = {"frames": self.frames, "tracked": self.tracked, "map_points": self.map_points, **self.counts, **extra,
                 "updated": time.time(), "recent": list(self.recent)}  # entries are never changed once listed
        if self.legend is not None:  # replaced whole by the image writer, never changed in place
            state["frame_legend"] = self.legend
        if self._state is not None:
            self._state.put(lambda: json.dumps(state).encode())
        else:
            self._put(artifacts.PARTIAL_STATE, json.dumps(state).encode())

    def _put(self, name: str, data: bytes) -> None:
        """Write a snapshot file under a hidden name and rename it (readers never see half of one); no fsync: the
        file is rewritten soon and worthless after a crash (the artifact store's fsync cost ~10 ms a file)."""
        folder = self.store.job_dir(self.job_id, create=True)
        tmp = folder / f".{name}.tmp"
        tmp.write_bytes(data)
        os.replace(tmp, folder / name)

    def _write_full(self, run: PipelineRun, frame: Frame, inputs: FrameInputs) -> None:
        """Gather the snapshot on the pipeline thread (references and small copies, new keyframes back-projected),
        write it on the writer thread; a snapshot due while the last one is still being written is skipped."""
        if self._pending is not None and not self._pending.done():
            return
        snap = self._gather(run, frame, inputs)
        if self._pool is None:
            self._write(snap)
            return
        self._pending = self._pool.submit(self._write_logged, snap)

    def _gather(self, run: PipelineRun, frame: Frame, inputs: FrameInputs) -> _Snapshot:
        smap = run.parts.map
        K, stride = run.parts.sensor.K, run.config.dense.stride
        clouds = []
        for kf in smap.keyframes:
            cloud = self.clouds.get(kf.id)
            if cloud is None and kf.rgb_small is not None and kf.depth_small is not None:
                cloud = self.clouds[kf.id] = _backproject(kf.rgb_small, kf.depth_small, K, stride,
                                                          self.config.pixel_step)
            if cloud is not None and len(cloud.xyz):
                clouds.append((cloud, kf.T_WC.copy()))
        sparse = None
        if not clouds:  # no dense copies kept: the sparse map's points
            pts = smap.points
            sparse = pts.pos[: pts.n][pts.alive[: pts.n]].astype(np.float32)
        return _Snapshot(self.frames, list(self.stamps), list(self.poses), [kf.timestamp for kf in smap.keyframes],
                         [kf.T_WC.copy() for kf in smap.keyframes], clouds, sparse, frame.rgb,
                         inputs.potentially_dynamic, inputs.dynamic_mask, inputs.class_labels)

    def _write_logged(self, snap: _Snapshot) -> None:
        try:
            self._write(snap)
        except Exception as exc:  # noqa: BLE001 - as in __call__: the run goes on, the job's metrics say why
            self._failed(exc)

    def _failed(self, exc: Exception) -> None:
        if self.error is None:
            self.error = f"partial results not written: {type(exc).__name__}: {exc}"
            log.warning("job %s: %s", self.job_id, self.error)

    def _write(self, snap: _Snapshot) -> None:
        self._put(artifacts.PARTIAL_TRAJECTORY, _tum(snap.stamps, snap.poses).encode())
        self._put(artifacts.PARTIAL_KEYFRAMES, _tum(snap.kf_stamps, snap.kf_poses).encode())
        xyz, rgb = self._map(snap)
        self.map_points = len(xyz)
        write_ply(self.store.job_dir(self.job_id, create=True) / artifacts.PARTIAL_MAP, xyz, rgb)  # atomic
        self._write_images(snap)

    def _map(self, snap: _Snapshot) -> tuple[np.ndarray, np.ndarray]:
        """(M,3) float32 world points and (M,3) uint8 RGB of the map so far."""
        if snap.sparse is not None:
            return snap.sparse, np.full((len(snap.sparse), 3), 200, np.uint8)
        xyz = np.concatenate([c.xyz @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32)
                              for c, T in snap.clouds])
        rgb = np.concatenate([c.rgb for c, _ in snap.clouds])
        if len(xyz) > self.config.max_points:
            keep = np.random.default_rng(len(xyz)).choice(len(xyz), self.config.max_points, replace=False)
            xyz, rgb = xyz[keep], rgb[keep]
        return xyz, rgb

    def _write_images(self, snap: _Snapshot) -> None:
        import cv2

        rgb = snap.rgb
        for name, img in ((artifacts.PARTIAL_FRAME_RGB, rgb), (artifacts.PARTIAL_FRAME_MASK, self._overlay(snap))):
            ok, data = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 80])
            if ok:
                self._put(name, data.tobytes())

    def _overlay(self, snap: _Snapshot) -> np.ndarray:
        """The frame coloured by class (`formats.class_palette`; the moving pixels outlined), its legend kept for
        partial.json; without the network's classes (geometry only, truth masks) the potentially dynamic pixels
        in yellow, the moving ones in red."""
        rgb, seg = snap.rgb, snap.class_labels
        if seg is not None and seg.labels.shape == rgb.shape[:2]:
            self.legend = legend(present_classes(seg.labels, seg.classes), seg.dynamic_classes)
            return class_overlay(rgb, seg.labels, seg.classes, seg.dynamic_classes, snap.dynamic_mask)
        overlay = rgb.copy()
        for mask, colour in ((snap.potentially_dynamic, (250, 210, 40)), (snap.dynamic_mask, (230, 40, 30))):
            if mask is not None and mask.shape == rgb.shape[:2] and mask.any():
                overlay[mask] = (0.45 * overlay[mask] + 0.55 * np.array(colour)).astype(np.uint8)
        return overlay

    def close(self) -> None:
        """Wait for the snapshot and the state being written (none is written after)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        if self._state is not None:
            self._state.close()
            self._state = None

    def remove(self) -> None:
        """Drop the snapshot files (the job ended: its final artifacts, or nothing, replace them)."""
        self.close()
        folder = self.store.job_dir(self.job_id)
        for name in artifacts.PARTIALS:
            (folder / name).unlink(missing_ok=True)


def _backproject(rgb: np.ndarray, depth: np.ndarray, K: np.ndarray, stride: int, step: int) -> _Cloud:
    """Camera-frame points of every `step`-th pixel with depth of a keyframe's dense copy (`rgb` (h,w,3) uint8
    RGB, `depth` (h,w) float32 m, taken every `stride`-th pixel of the (H,W) image with intrinsics `K`)."""
    d = depth[::step, ::step]
    v, u = np.nonzero(d > 0)
    z = d[v, u].astype(np.float32)
    s = stride * step
    x = (u * s - K[0, 2]) / K[0, 0] * z
    y = (v * s - K[1, 2]) / K[1, 1] * z
    return _Cloud(np.stack([x, y, z], axis=1).astype(np.float32), rgb[::step, ::step][v, u].copy())


def _tum(stamps: list[float], poses: list[np.ndarray]) -> str:
    """TUM lines ``t tx ty tz qx qy qz qw`` of (4,4) T_WC poses."""
    from scipy.spatial.transform import Rotation

    if not poses:
        return ""
    P = np.stack(poses)
    q = Rotation.from_matrix(P[:, :3, :3]).as_quat()  # x y z w
    return "".join(f"{t:.6f} {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {a:.6f} {b:.6f} {c:.6f} {d:.6f}\n"
                   for t, p, (a, b, c, d) in zip(stamps, P[:, :3, 3], q, strict=True))
