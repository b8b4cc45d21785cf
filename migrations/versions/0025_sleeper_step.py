"""The step estimate of the sleeper-passage amplitude stored with the profiles: profile_bins.sleeper_step.

Issue 33 item 7: the levels of ``sleeper_amp`` between change points (m/s²,
app.pipeline.assemble.sleeper_step). Rows of jobs processed before this revision keep NULL: the
profile API says the job stored no step estimate; reprocessing the run fills it.

Revision ID: 0025_sleeper_step
Revises: 0024_user_language
Create Date: 2026-11-29
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0025_sleeper_step"
down_revision: str | None = "0024_user_language"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # a nullable column without a default: SQLite and PostgreSQL add it without rewriting the rows
    op.add_column("profile_bins", sa.Column("sleeper_step", sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("profile_bins") as batch:
        batch.drop_column("sleeper_step")
