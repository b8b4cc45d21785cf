"""The stated 1-sigma of a place's size: level_sd, change_sd, severity_sd on places and their observations.

Revision ID: 0020_place_uncertainty
Revises: 0019_places_pending
Create Date: 2026-11-26
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0020_place_uncertainty"
down_revision: str | None = "0019_places_pending"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_COLUMNS = ("level_sd", "change_sd", "severity_sd")


def upgrade() -> None:
    for table in ("places", "place_observations"):
        with op.batch_alter_table(table) as batch:
            for name in _COLUMNS:
                batch.add_column(sa.Column(name, sa.Float(), nullable=True))


def downgrade() -> None:
    for table in ("places", "place_observations"):
        with op.batch_alter_table(table) as batch:
            for name in reversed(_COLUMNS):
                batch.drop_column(name)
