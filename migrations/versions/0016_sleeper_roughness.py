"""profile_bins: the single-wheel sleeper amplitude and the 1-σ of the best estimate (issue 26).

``sleeper_amp`` becomes the best estimate of the sleeper-passage response with
the rail roughness taken out as far as one pass allows (floor-corrected for a
single wheel, common to both rails for an axle with both wheels measured); two
nullable columns beside it: ``sleeper_amp_raw`` (the single-wheel VKF amplitude
at f_s, what ``sleeper_amp`` held before, m/s²), ``sleeper_amp_sd`` (the 1-σ
of ``sleeper_amp``, m/s²) and ``sleeper_amp_sd_shared`` (the part of that 1-σ
shared along the ≈ 20 m window the floors are estimated over, m/s²). Rows stored
before have NULL there. On PostgreSQL
the columns added to the partitioned table reach every partition.

Revision ID: 0016_sleeper_roughness
Revises: 0015_track_impacts
Create Date: 2026-11-26
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0016_sleeper_roughness"
down_revision: str | None = "0015_track_impacts"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_COLUMNS = ("sleeper_amp_raw", "sleeper_amp_sd", "sleeper_amp_sd_shared")


def upgrade() -> None:
    for name in _COLUMNS:
        op.add_column("profile_bins", sa.Column(name, sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("profile_bins") as batch:
        for name in reversed(_COLUMNS):
            batch.drop_column(name)
