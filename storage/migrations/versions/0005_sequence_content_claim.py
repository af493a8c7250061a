"""sequences.claimed_sha256: a unique copy of content_sha256, so the database refuses a second upload
of the same archive even when two arrive together (the api's look-up alone lets both through)

Revision ID: 0005_sequence_content_claim
Revises: 0004_sequence_content_hash
Create Date: 2026-12-02
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005_sequence_content_claim"
down_revision: str | None = "0004_sequence_content_hash"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# The oldest sequence of each archive claims it (the one the 409 names, storage.repositories.sequences
# .find_by_content); copies added with allow_duplicate keep NULL, which a unique index lets repeat.
_BACKFILL = """
UPDATE sequences SET claimed_sha256 = content_sha256
WHERE content_sha256 IS NOT NULL AND NOT EXISTS (
    SELECT 1 FROM sequences AS older
    WHERE older.content_sha256 = sequences.content_sha256
      AND (older.created_at < sequences.created_at
           OR (older.created_at = sequences.created_at AND older.id < sequences.id))
)
"""


def upgrade() -> None:
    op.add_column("sequences", sa.Column("claimed_sha256", sa.String(64), nullable=True))
    op.execute(_BACKFILL)
    op.create_index("ix_sequences_claimed_sha256", "sequences", ["claimed_sha256"], unique=True)


def downgrade() -> None:
    op.drop_index("ix_sequences_claimed_sha256", table_name="sequences")
    with op.batch_alter_table("sequences") as batch:
        batch.drop_column("claimed_sha256")
