"""sequences.content_sha256: the uploaded archive's SHA-256, to answer a second upload of the same file

Revision ID: 0004_sequence_content_hash
Revises: 0003_requeues
Create Date: 2026-12-02
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004_sequence_content_hash"
down_revision: str | None = "0003_requeues"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # Nullable: sequences registered in place, and those uploaded before this revision, have no hash.
    op.add_column("sequences", sa.Column("content_sha256", sa.String(64), nullable=True))
    op.create_index("ix_sequences_content_sha256", "sequences", ["content_sha256"])


def downgrade() -> None:
    op.drop_index("ix_sequences_content_sha256", table_name="sequences")
    with op.batch_alter_table("sequences") as batch:
        batch.drop_column("content_sha256")
