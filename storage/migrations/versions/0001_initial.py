"""initial schema: sequences, batches, jobs, run_metrics, frame_stats

Revision ID: 0001_initial
Revises:
Create Date: 2025-11-21
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0001_initial"
down_revision: str | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# Frozen copies of the types at this revision: a migration must not change when the models do.
TS = sa.DateTime(timezone=True)
ID = sa.String(32)


def upgrade() -> None:
    op.create_table(
        "sequences",
        sa.Column("id", ID, nullable=False),
        sa.Column("name", sa.String(255), nullable=False),
        sa.Column("path", sa.String(1024), nullable=False),
        sa.Column("frames", sa.Integer(), nullable=False),
        sa.Column("duration_s", sa.Double(), nullable=False),
        sa.Column("has_groundtruth", sa.Boolean(), nullable=False),
        sa.Column("camera", sa.JSON(), nullable=False),
        sa.Column("created_at", TS, nullable=False),
        sa.Column("size_bytes", sa.BigInteger(), nullable=False),
        sa.Column("meta", sa.JSON(), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_sequences"),
    )
    op.create_index("ix_sequences_created_at", "sequences", ["created_at"])

    op.create_table(
        "batches",
        sa.Column("id", ID, nullable=False),
        sa.Column("name", sa.String(255), nullable=False),
        sa.Column("created_at", TS, nullable=False),
        sa.Column("sequence_ids", sa.JSON(), nullable=False),
        sa.Column("presets", sa.JSON(), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_batches"),
    )
    op.create_index("ix_batches_created_at", "batches", ["created_at"])

    op.create_table(
        "jobs",
        sa.Column("id", ID, nullable=False),
        sa.Column("sequence_id", ID, nullable=False),
        sa.Column("batch_id", ID, nullable=True),
        sa.Column("preset", sa.String(64), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("progress", sa.Double(), nullable=False),
        sa.Column("stage", sa.String(64), nullable=False),
        sa.Column("frames_done", sa.Integer(), nullable=False),
        sa.Column("frames_total", sa.Integer(), nullable=False),
        sa.Column("config", sa.JSON(), nullable=False),
        sa.Column("error", sa.Text(), nullable=True),
        sa.Column("timings", sa.JSON(), nullable=False),
        sa.Column("created_at", TS, nullable=False),
        sa.Column("started_at", TS, nullable=True),
        sa.Column("finished_at", TS, nullable=True),
        sa.Column("worker", sa.String(255), nullable=True),
        sa.Column("attempts", sa.Integer(), nullable=False),
        sa.Column("cancel_requested", sa.Boolean(), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_jobs"),
        sa.ForeignKeyConstraint(
            ["sequence_id"], ["sequences.id"], name="fk_jobs_sequence_id_sequences", ondelete="CASCADE"
        ),
        sa.ForeignKeyConstraint(
            ["batch_id"], ["batches.id"], name="fk_jobs_batch_id_batches", ondelete="SET NULL"
        ),
    )
    op.create_index("ix_jobs_sequence_id", "jobs", ["sequence_id"])
    op.create_index("ix_jobs_batch_id", "jobs", ["batch_id"])
    op.create_index("ix_jobs_created_at", "jobs", ["created_at"])
    op.create_index("ix_jobs_status_created_at", "jobs", ["status", "created_at"])

    op.create_table(
        "run_metrics",
        sa.Column("job_id", ID, nullable=False),
        *(
            sa.Column(name, sa.Double(), nullable=True)
            for name in (
                "ate_rmse", "ate_mean", "ate_median", "ate_std", "ate_max",
                "rpe_trans_rmse", "rpe_rot_rmse", "fps",
            )
        ),
        sa.Column("tracked", sa.Integer(), nullable=True),
        sa.Column("lost", sa.Integer(), nullable=True),
        sa.Column("metrics", sa.JSON(), nullable=False),
        sa.PrimaryKeyConstraint("job_id", name="pk_run_metrics"),
        sa.ForeignKeyConstraint(
            ["job_id"], ["jobs.id"], name="fk_run_metrics_job_id_jobs", ondelete="CASCADE"
        ),
    )

    op.create_table(
        "frame_stats",
        sa.Column("job_id", ID, nullable=False),
        sa.Column("frame_index", sa.Integer(), nullable=False),
        sa.Column("timestamp", sa.Double(), nullable=False),
        sa.Column("tracked", sa.Boolean(), nullable=False),
        sa.Column("n_features", sa.Integer(), nullable=False),
        sa.Column("n_dynamic_removed", sa.Integer(), nullable=False),
        sa.Column("ate_error", sa.Double(), nullable=True),
        sa.Column("timings", sa.JSON(), nullable=False),
        sa.PrimaryKeyConstraint("job_id", "frame_index", name="pk_frame_stats"),
        sa.ForeignKeyConstraint(
            ["job_id"], ["jobs.id"], name="fk_frame_stats_job_id_jobs", ondelete="CASCADE"
        ),
    )


def downgrade() -> None:
    op.drop_table("frame_stats")
    op.drop_table("run_metrics")
    for name in (
        "ix_jobs_status_created_at", "ix_jobs_created_at", "ix_jobs_batch_id", "ix_jobs_sequence_id"
    ):
        op.drop_index(name, table_name="jobs")
    op.drop_table("jobs")
    op.drop_index("ix_batches_created_at", table_name="batches")
    op.drop_table("batches")
    op.drop_index("ix_sequences_created_at", table_name="sequences")
    op.drop_table("sequences")
