"""SQLAlchemy ORM models. Schema changes go through an Alembic revision in ``storage/migrations``."""

from __future__ import annotations

import enum
import uuid
from datetime import datetime
from typing import Any

from sqlalchemy import JSON, BigInteger, Enum, ForeignKey, Index, MetaData, String, Text
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

from storage.sqltypes import UTCDateTime, utcnow

# Deterministic constraint names: Alembic can then drop/alter them on SQLite (batch mode) and PostgreSQL.
NAMING_CONVENTION = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def new_id() -> str:
    return uuid.uuid4().hex


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)
    type_annotation_map = {datetime: UTCDateTime(), dict[str, Any]: JSON(), list[Any]: JSON()}


class JobStatus(enum.StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"

    @property
    def is_terminal(self) -> bool:
        return self in TERMINAL_STATUSES


TERMINAL_STATUSES = frozenset({JobStatus.SUCCEEDED, JobStatus.FAILED, JobStatus.CANCELLED})


class Sequence(Base):
    """An uploaded or registered RGB-D sequence (TUM layout) under the data directory."""

    __tablename__ = "sequences"

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    name: Mapped[str] = mapped_column(String(255))
    path: Mapped[str] = mapped_column(String(1024))  # relative to the data dir (or absolute if registered)
    frames: Mapped[int] = mapped_column(default=0)
    duration_s: Mapped[float] = mapped_column(default=0.0)
    has_groundtruth: Mapped[bool] = mapped_column(default=False)
    camera: Mapped[dict[str, Any]] = mapped_column(default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)
    size_bytes: Mapped[int] = mapped_column(BigInteger, default=0)
    meta: Mapped[dict[str, Any]] = mapped_column(default=dict)
    # SHA-256 of the uploaded archive as it arrived: a second upload of the same file is refused (409).
    content_sha256: Mapped[str | None] = mapped_column(String(64), index=True)
    # The same hash on the one sequence that holds the archive against duplicates (NULL on copies added
    # with allow_duplicate): unique, so two uploads of one archive racing past the look-up cannot both land.
    claimed_sha256: Mapped[str | None] = mapped_column(String(64), index=True, unique=True)

    # The database cascades the delete (passive_deletes): no job rows are loaded to remove them.
    jobs: Mapped[list[Job]] = relationship(
        back_populates="sequence", cascade="all, delete-orphan", passive_deletes=True
    )


class Batch(Base):
    """A comparison run: every sequence under every preset (one job each)."""

    __tablename__ = "batches"

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    name: Mapped[str] = mapped_column(String(255), default="")
    created_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)
    sequence_ids: Mapped[list[Any]] = mapped_column(default=list)
    presets: Mapped[list[Any]] = mapped_column(default=list)


class Job(Base):
    """One pipeline run of a sequence under a preset; the worker reports progress here."""

    __tablename__ = "jobs"
    __table_args__ = (Index("ix_jobs_status_created_at", "status", "created_at"),)

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    sequence_id: Mapped[str] = mapped_column(
        ForeignKey("sequences.id", ondelete="CASCADE"), index=True
    )
    batch_id: Mapped[str | None] = mapped_column(
        ForeignKey("batches.id", ondelete="SET NULL"), index=True
    )
    preset: Mapped[str] = mapped_column(String(64))
    # Stored as its string value (VARCHAR, no native enum): adding a status needs no type migration.
    status: Mapped[JobStatus] = mapped_column(
        Enum(
            JobStatus,
            native_enum=False,
            length=16,
            values_callable=lambda e: [m.value for m in e],
            validate_strings=True,
        ),
        default=JobStatus.QUEUED,
    )
    progress: Mapped[float] = mapped_column(default=0.0)  # 0..1
    stage: Mapped[str] = mapped_column(String(64), default="")
    frames_done: Mapped[int] = mapped_column(default=0)
    frames_total: Mapped[int] = mapped_column(default=0)
    config: Mapped[dict[str, Any]] = mapped_column(default=dict)  # snapshot the run used
    error: Mapped[str | None] = mapped_column(Text)
    timings: Mapped[dict[str, Any]] = mapped_column(default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)
    started_at: Mapped[datetime | None]
    heartbeat_at: Mapped[datetime | None]  # last sign of life of the running worker (claim, progress)
    finished_at: Mapped[datetime | None]
    worker: Mapped[str | None] = mapped_column(String(255))
    attempts: Mapped[int] = mapped_column(default=1)  # how many times it was queued (1 + retries + requeues)
    # automatic requeues after its worker died (bounded by Settings.requeue_orphans; a manual retry resets it)
    requeues: Mapped[int] = mapped_column(default=0, server_default="0")
    cancel_requested: Mapped[bool] = mapped_column(default=False)

    sequence: Mapped[Sequence] = relationship(back_populates="jobs")
    # selectin: a job is nearly always shown with its metrics, and it stays readable after the session.
    metrics: Mapped[RunMetrics | None] = relationship(
        lazy="selectin", cascade="all, delete-orphan", passive_deletes=True
    )


class RunMetrics(Base):
    """Summary metrics of a finished job; ``metrics`` keeps the full ``metrics.json`` blob."""

    __tablename__ = "run_metrics"

    job_id: Mapped[str] = mapped_column(
        ForeignKey("jobs.id", ondelete="CASCADE"), primary_key=True
    )
    ate_rmse: Mapped[float | None]
    ate_mean: Mapped[float | None]
    ate_median: Mapped[float | None]
    ate_std: Mapped[float | None]
    ate_max: Mapped[float | None]
    rpe_trans_rmse: Mapped[float | None]
    rpe_rot_rmse: Mapped[float | None]
    fps: Mapped[float | None]
    tracked: Mapped[int | None]
    lost: Mapped[int | None]
    metrics: Mapped[dict[str, Any]] = mapped_column(default=dict)


class FrameStat(Base):
    """Per-frame diagnostics of a job (plots in the dashboard)."""

    __tablename__ = "frame_stats"

    job_id: Mapped[str] = mapped_column(
        ForeignKey("jobs.id", ondelete="CASCADE"), primary_key=True
    )
    frame_index: Mapped[int] = mapped_column(primary_key=True)
    timestamp: Mapped[float]
    tracked: Mapped[bool] = mapped_column(default=True)
    n_features: Mapped[int] = mapped_column(default=0)
    n_dynamic_removed: Mapped[int] = mapped_column(default=0)
    ate_error: Mapped[float | None]
    timings: Mapped[dict[str, Any]] = mapped_column(default=dict)
