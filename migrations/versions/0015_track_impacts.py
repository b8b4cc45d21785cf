"""profile_bins: track impacts (dipped welds and joints) as a column.

One nullable column: ``track_impact_mm``, the estimated depth (mm) of an
isolated track impact found in that bin (app.pipeline.impacts); NULL
elsewhere and in rows stored before; and a partial index over the few rows
that hold one (a run's list of impacts reads them without scanning its
~10⁶ rows). On PostgreSQL both go onto the partitioned table and so onto
every partition.

Revision ID: 0015_track_impacts
Revises: 0014_operations
Create Date: 2026-11-26
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0015_track_impacts"
down_revision: str | None = "0014_operations"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


_WHERE = "track_impact_mm IS NOT NULL"


def upgrade() -> None:
    op.add_column("profile_bins", sa.Column("track_impact_mm", sa.Float(), nullable=True))
    op.create_index("ix_profile_bins_track_impacts", "profile_bins", ["job_id", "km"],
                    postgresql_where=sa.text(_WHERE), sqlite_where=sa.text(_WHERE))


def downgrade() -> None:
    op.drop_index("ix_profile_bins_track_impacts", table_name="profile_bins")
    with op.batch_alter_table("profile_bins") as batch:
        batch.drop_column("track_impact_mm")
