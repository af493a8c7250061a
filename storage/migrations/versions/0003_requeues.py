"""jobs.requeues: how often a job was requeued automatically after its worker died

Revision ID: 0003_requeues
Revises: 0002_heartbeat
Create Date: 2026-11-22
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003_requeues"
down_revision: str | None = "0002_heartbeat"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # server_default: existing rows get 0 without a table rewrite on PostgreSQL.
    op.add_column("jobs", sa.Column("requeues", sa.Integer(), nullable=False, server_default="0"))


def downgrade() -> None:
    with op.batch_alter_table("jobs") as batch:
        batch.drop_column("requeues")
