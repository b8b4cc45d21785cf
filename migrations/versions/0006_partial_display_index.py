"""profile_bins: the display index covers only the coarse display levels.

The full index ``(job_id, wheel, km, display_level)`` of 0005 was a third of
PostgreSQL's work when a run's ~10⁶ rows are stored, and two workers storing
wheels at once contended on its pages. It is replaced by the same index over
the rows of display level >= 2 (one row in eight): plots of long ranges read
those; short km ranges (levels 0 and 1) and whole-profile reads go through the
primary key ``(job_id, wheel, bin)`` as bin ranges
(:func:`app.db.results_reader.profile_where`).

Revision ID: 0006_partial_display_index
Revises: 0005_profile_display_levels
Create Date: 2026-11-22
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006_partial_display_index"
down_revision: str | None = "0005_profile_display_levels"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

#: app.db.models.COARSE_DISPLAY_LEVEL when this revision was written (a migration keeps its own copy)
_COARSE = 2
_COLUMNS = ["job_id", "wheel", "km", "display_level"]


def upgrade() -> None:
    op.drop_index("ix_profile_bins_job_id_wheel_km_level", table_name="profile_bins")
    where = sa.text(f"display_level >= {_COARSE}")
    op.create_index(
        "ix_profile_bins_coarse_display", "profile_bins", _COLUMNS, postgresql_where=where, sqlite_where=where
    )


def downgrade() -> None:
    op.drop_index("ix_profile_bins_coarse_display", table_name="profile_bins")
    op.create_index("ix_profile_bins_job_id_wheel_km_level", "profile_bins", _COLUMNS)
