"""profile_bins: the sleeper-passage harmonics and energy indicator.

Three nullable columns beside ``sleeper_amp`` (the fundamental f_s): the peak
amplitudes of the harmonics 2·f_s and 3·f_s (``sleeper_2_amp``,
``sleeper_3_amp``, m/s²) and the RMS of the sleeper-passage signal over the
fundamental and the harmonics extracted (``sleeper_rms``, m/s²). Rows stored
before have NULL there.

Revision ID: 0009_sleeper_harmonics
Revises: 0008_audit_login_failures
Create Date: 2026-11-24
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0009_sleeper_harmonics"
down_revision: str | None = "0008_audit_login_failures"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_COLUMNS = ("sleeper_2_amp", "sleeper_3_amp", "sleeper_rms")


def upgrade() -> None:
    for name in _COLUMNS:
        op.add_column("profile_bins", sa.Column(name, sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("profile_bins") as batch:
        for name in reversed(_COLUMNS):
            batch.drop_column(name)
