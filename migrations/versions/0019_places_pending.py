"""The places follow-up of the publish step: the runs whose places update is still to be done (issue 24).

Revision ID: 0019_places_pending
Revises: 0018_assets
Create Date: 2026-11-26
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0019_places_pending"
down_revision: str | None = "0018_assets"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "places_pending",
        sa.Column("run_id", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("line_key", sa.Integer(), nullable=False),
        sa.Column("job_id", sa.Integer(), nullable=False),
        sa.Column("run_time", sa.DateTime(), nullable=False),
        sa.Column("queued_at", sa.DateTime(), nullable=False),
        sa.Column("attempts", sa.Integer(), nullable=False),
        sa.Column("next_attempt_at", sa.DateTime(), nullable=True),
        sa.Column("last_error", sa.Text(), nullable=True),
        sa.Column("gave_up", sa.Boolean(), nullable=False),
        sa.PrimaryKeyConstraint("run_id", name=op.f("pk_places_pending")),
    )
    op.create_index("ix_places_pending_line_key_run_time", "places_pending", ["line_key", "run_time"])


def downgrade() -> None:
    op.drop_index("ix_places_pending_line_key_run_time", table_name="places_pending")
    op.drop_table("places_pending")
