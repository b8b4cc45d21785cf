"""reference_curves: the cached reference curves of the stiffness index, one row per line and track.

Revision ID: 0010_reference_curves
Revises: 0009_sleeper_harmonics
Create Date: 2026-11-24
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op
from sqlalchemy.dialects import postgresql

revision: str = "0010_reference_curves"
down_revision: str | None = "0009_sleeper_harmonics"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

JSONType = sa.JSON().with_variant(postgresql.JSONB(), "postgresql")


def upgrade() -> None:
    op.create_table(
        "reference_curves",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("line_id", sa.String(length=128), nullable=False),
        sa.Column("track", sa.String(length=64), nullable=False),
        sa.Column("fingerprint", sa.String(length=64), nullable=False),
        sa.Column("run_ids", JSONType, nullable=False),
        sa.Column("job_ids", JSONType, nullable=False),
        sa.Column("body", JSONType, nullable=False),
        sa.Column("computed_at", sa.DateTime(), nullable=False),
        sa.Column("compute_s", sa.Float(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_reference_curves")),
        sa.UniqueConstraint("line_id", "track", name="uq_reference_curves_line_id_track"),
    )


def downgrade() -> None:
    op.drop_table("reference_curves")
