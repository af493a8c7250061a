"""Response and request bodies, with the examples OpenAPI shows."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Annotated, Any, Generic, TypeVar

from fastapi import Path
from pydantic import BaseModel, ConfigDict, Field

from formats import artifacts
from formats.camera_spec import groundtruth_frame_of
from formats.run_metrics import with_current_spelling
from storage.live import STREAMING_STAGE
from storage.models import Batch, Job, JobStatus, Sequence
from storage.presets import DEFAULT_PIPELINE_PRESET
from storage.repositories.batches import ComparisonRow
from storage.repositories.jobs import FINISHED_STAGE, run_seconds, timings_ms

T = TypeVar("T")

_SEQ_ID = "3f2c9a7e0b1d4c5e8f6a7b8c9d0e1f2a"
_JOB_ID = "9b8a7c6d5e4f43a2b1c0d9e8f7a6b5c4"
_BATCH_ID = "5d4c3b2a1f0e4d9c8b7a6f5e4d3c2b1a"

# Path parameters with examples: the docs show a real-looking id, and the api's fuzz test seeds these
# very ids so its generated requests reach existing resources, not only 404s.
SequenceId = Annotated[str, Path(description="A sequence's id.", examples=[_SEQ_ID])]
JobId = Annotated[str, Path(description="A job's id.", examples=[_JOB_ID])]
BatchId = Annotated[str, Path(description="A batch's id.", examples=[_BATCH_ID])]
ArtifactName = Annotated[str, Path(description="A file the run wrote.", examples=[artifacts.TRAJECTORY])]


class LatestJob(BaseModel):
    """A sequence's newest job, as the sequence list shows it."""

    id: str
    preset: str
    status: JobStatus
    progress: float
    created_at: datetime
    finished_at: datetime | None

    @classmethod
    def of(cls, job: Job) -> LatestJob:
        return cls(
            id=job.id,
            preset=job.preset,
            status=job.status,
            progress=job.progress,
            created_at=job.created_at,
            finished_at=job.finished_at,
        )


class SequenceOut(BaseModel):
    id: str
    name: str
    frames: int
    duration_s: float
    has_groundtruth: bool
    groundtruth_frame: str = Field(
        "camera", description="what groundtruth.txt is the pose of: camera, or bonn-marker (Bonn's motion-capture "
        "marker: RPE and the corrected ATE use it moved to the camera); set by the camera (preset bonn, or "
        "groundtruth_frame in explicit intrinsics or the folder's camera.json)")
    camera: dict[str, Any]
    size_bytes: int
    created_at: datetime
    meta: dict[str, Any]
    thumbnail_url: str
    content_sha256: str | None = Field(description="SHA-256 of the uploaded archive (None if registered).")
    latest_job: LatestJob | None = Field(description="The sequence's newest job, if any.")

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "id": _SEQ_ID,
                    "name": "rgbd_dataset_freiburg3_walking_xyz",
                    "frames": 827,
                    "duration_s": 28.83,
                    "has_groundtruth": True,
                    "groundtruth_frame": "camera",
                    "camera": {"preset": "tum3"},
                    "size_bytes": 512000000,
                    "created_at": "2026-01-01T12:00:00Z",
                    "meta": {"width": 640, "height": 480, "gt_poses": 2864, "source": "upload"},
                    "thumbnail_url": f"/api/v1/sequences/{_SEQ_ID}/thumbnail",
                    "content_sha256": "9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08",
                    "latest_job": None,
                }
            ]
        }
    )

    @classmethod
    def of(cls, seq: Sequence, latest_job: Job | None = None) -> SequenceOut:
        return cls(
            id=seq.id,
            name=seq.name,
            frames=seq.frames,
            duration_s=seq.duration_s,
            has_groundtruth=seq.has_groundtruth,
            groundtruth_frame=groundtruth_frame_of((seq.meta or {}).get("camera_file") or seq.camera),
            camera=seq.camera,
            size_bytes=seq.size_bytes,
            created_at=seq.created_at,
            meta=seq.meta,
            thumbnail_url=f"/api/v1/sequences/{seq.id}/thumbnail",
            content_sha256=seq.content_sha256,
            latest_job=LatestJob.of(latest_job) if latest_job is not None else None,
        )


class SequenceImport(BaseModel):
    """Register a folder already on the server (below ``VTD_IMPORT_ROOT``) without copying it."""

    path: str = Field(min_length=1, max_length=1024, examples=["tum/rgbd_dataset_freiburg3_walking_xyz"])
    camera: str | dict[str, Any] = Field(examples=["tum3"])
    name: str | None = Field(default=None, max_length=255)

    model_config = ConfigDict(extra="forbid")


class Page(BaseModel, Generic[T]):
    items: list[T]
    total: int | None = Field(description="All matching items (None where not counted).")
    limit: int
    offset: int


class JobCreate(BaseModel):
    sequence_id: str = Field(min_length=1, max_length=64, examples=[_SEQ_ID])
    preset: str = Field(
        default=DEFAULT_PIPELINE_PRESET, min_length=1, max_length=64, examples=["orb-only"],
        description=f"Pipeline preset (default {DEFAULT_PIPELINE_PRESET}).",
    )
    config: dict[str, Any] | None = Field(
        default=None,
        description="Config overrides, nested or dotted (validated by the worker; a bad one fails the job).",
        examples=[{"tracking.min_matches": 25, "dense": {"voxel_m": 0.02}}],
    )

    model_config = ConfigDict(extra="forbid")


class JobOut(BaseModel):
    id: str
    sequence_id: str
    batch_id: str | None
    preset: str
    status: JobStatus
    progress: float
    stage: str = Field(description="The running job's step: starting, tracking, dense, evaluation, writing, saving "
                       "(a live session: waiting for frames, live while its stream is open, then finishing); "
                       f"{FINISHED_STAGE!r} once it succeeded or was cancelled; a failed job keeps the step "
                       "it failed in (empty if it failed before its first step); empty while queued.")
    frames_done: int
    frames_total: int
    eta_s: float | None = Field(description="Estimated seconds left for the frames still to track, at the rate so "
                                "far; null once every frame is tracked (the run is finishing: dense map, evaluation, "
                                "saving), while a live session's stream is open (stage 'live': frames_total is what "
                                "it received so far) and when the job is not running.")
    config: dict[str, Any]
    error: str | None
    timings: dict[str, Any] = Field(description="All milliseconds: the run's mean time per call by step (as "
                                    "metrics.json's timings_ms) and run_ms, the whole pipeline call. Jobs stored "
                                    "before had run_s (seconds) here: shown as run_ms.")
    run_s: float | None = Field(default=None, description="Seconds the pipeline ran (timings.run_ms / 1000); null "
                                "until the job succeeded.")
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    worker: str | None
    attempts: int = Field(description="How many times the job was queued: 1 + manual retries + automatic requeues.")
    requeues: int = Field(description="Automatic requeues after its worker died (reset by a manual retry).")
    cancel_requested: bool
    metrics: dict[str, Any] | None = Field(
        description="The run's metrics.json once it succeeded (keys and units: formats.run_metrics.RunMetrics; an "
        "old run's RPE also under today's names rpe.trans and rpe.rot_deg).")

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "id": _JOB_ID,
                    "sequence_id": _SEQ_ID,
                    "batch_id": None,
                    "preset": "orb-only",
                    "status": "running",
                    "progress": 0.42,
                    "stage": "tracking",
                    "frames_done": 347,
                    "frames_total": 827,
                    "eta_s": 31.5,
                    "config": {},
                    "error": None,
                    "timings": {},
                    "run_s": None,
                    "created_at": "2026-01-01T12:00:00Z",
                    "started_at": "2026-01-01T12:00:01Z",
                    "finished_at": None,
                    "worker": "host-1",
                    "attempts": 1,
                    "requeues": 0,
                    "cancel_requested": False,
                    "metrics": None,
                }
            ]
        }
    )

    @classmethod
    def of(cls, job: Job) -> JobOut:
        return cls(
            id=job.id,
            sequence_id=job.sequence_id,
            batch_id=job.batch_id,
            preset=job.preset,
            status=job.status,
            progress=job.progress,
            stage=job.stage,
            frames_done=job.frames_done,
            frames_total=job.frames_total,
            eta_s=eta_seconds(job),
            config=job.config,
            error=job.error,
            timings=timings_ms(job.timings),
            run_s=run_seconds(job.timings),
            created_at=job.created_at,
            started_at=job.started_at,
            finished_at=job.finished_at,
            worker=job.worker,
            attempts=job.attempts,
            requeues=job.requeues,
            cancel_requested=job.cancel_requested,
            metrics=with_current_spelling(job.metrics.metrics) if job.metrics is not None else None,
        )


def eta_seconds(job: Job) -> float | None:
    """Seconds left for the frames still to track at the rate so far; None once they are all tracked: the stages
    after the frame loop (dense map, evaluation, saving) report no progress to extrapolate, and "0 s left" for as
    long as they take would be wrong (the dashboard says "finishing" instead)."""
    if job.status != JobStatus.RUNNING or job.started_at is None or job.frames_done <= 0:
        return None
    if job.frames_done >= job.frames_total or job.stage == STREAMING_STAGE:  # an open stream's end is unknown
        return None
    elapsed = (datetime.now(UTC) - job.started_at).total_seconds()
    left = max(0, job.frames_total - job.frames_done)
    return round(elapsed / job.frames_done * left, 1)


class FrameOut(BaseModel):
    """One frame's statistics (formats.frame_stats.FrameStats)."""

    frame_index: int
    timestamp: float = Field(description="seconds, the sequence's clock")
    tracked: bool
    n_features: int = Field(description="ORB keypoints the tracker saw")
    n_dynamic_removed: int = Field(description="keypoints culled as dynamic")
    ate_error: float | None = Field(description="metres after SE(3) alignment; null without a matched ground truth")
    timings: dict[str, Any] = Field(description="milliseconds by step, where reported")


class ArtifactOut(BaseModel):
    name: str
    size_bytes: int
    content_type: str
    url: str


class BatchCreate(BaseModel):
    sequence_ids: list[str] = Field(min_length=1, max_length=100, examples=[[_SEQ_ID]])
    presets: list[str] = Field(min_length=1, max_length=20, examples=[["orb-only"]])
    name: str = Field(default="", max_length=255, examples=["paper table 2"])
    config: dict[str, Any] | None = Field(default=None, description="Config overrides for every job.")

    model_config = ConfigDict(extra="forbid")


class BatchOut(BaseModel):
    id: str
    name: str
    created_at: datetime
    sequence_ids: list[str]
    presets: list[str]
    status: str = Field(description="queued, running, finished (all jobs ended) or empty.")
    counts: dict[str, int] = Field(description="Jobs per status.")
    jobs: list[JobOut]

    @classmethod
    def of(cls, batch: Batch, jobs: list[Job]) -> BatchOut:
        counts: dict[str, int] = {}
        for j in jobs:
            counts[j.status.value] = counts.get(j.status.value, 0) + 1
        if not jobs:
            status = "empty"
        elif all(j.status.is_terminal for j in jobs):
            status = "finished"
        elif any(j.status != JobStatus.QUEUED for j in jobs):
            status = "running"
        else:
            status = "queued"
        return cls(
            id=batch.id,
            name=batch.name,
            created_at=batch.created_at,
            sequence_ids=list(batch.sequence_ids),
            presets=list(batch.presets),
            status=status,
            counts=counts,
            jobs=[JobOut.of(j) for j in jobs],
        )


class TableRow(BaseModel):
    sequence_id: str
    sequence_name: str | None
    preset: str
    job_id: str | None
    status: str | None
    ate_rmse: float | None = Field(description="metres")
    rpe_trans_rmse: float | None = Field(description="metres per RPE interval")
    rpe_rot_rmse: float | None = Field(description="degrees per RPE interval")
    fps: float | None
    relocalisations: int | None = Field(description="times tracking was lost and found again")
    mask_iou: float | None = Field(description="culled-region IoU against the true moving-object masks")
    feature_precision: float | None = Field(description="removed features that were on true movers")
    feature_recall: float | None = Field(description="features on true movers that were removed")
    restoration_psnr: float | None = Field(description="dB, restored against the true background")
    groundtruth_frame: str | None = Field(
        None, description="what the ground truth is the pose of: camera, or bonn-marker (Bonn's motion-capture marker)")
    ate_against: str | None = Field(None, description="what ate_rmse was measured against (raw ground truth)")
    ate_corrected_rmse: float | None = Field(None, description="metres, ATE against the camera's ground truth")
    ate_corrected_against: str | None = Field(None, description="what ate_corrected_rmse was measured against")
    rpe_against: str | None = Field(None, description="what the RPE figures were measured against")
    rpe_frame_trans_rmse: float | None = Field(None, description="metres per frame (consecutive poses)")
    rpe_frame_rot_rmse: float | None = Field(None, description="degrees per frame (consecutive poses)")

    @classmethod
    def of(cls, row: ComparisonRow) -> TableRow:
        return cls(**row.as_dict())


class Health(BaseModel):
    status: str = Field(examples=["ok"])
    version: str = Field(examples=["0.1.0"])
    database: str = Field(examples=["ok"])
