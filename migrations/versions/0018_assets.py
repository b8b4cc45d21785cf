"""Known discontinuities: the assets table (switches, crossings, bridges, level crossings, joints, welds).

Revision ID: 0018_assets
Revises: 0017_places
Create Date: 2026-11-26
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0018_assets"
down_revision: str | None = "0017_places"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "assets",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("line_id", sa.String(length=128), nullable=False),
        sa.Column("track", sa.String(length=64), nullable=True),
        sa.Column("type", sa.String(length=32), nullable=False),
        sa.Column("km", sa.Float(), nullable=False),
        sa.Column("km_to", sa.Float(), nullable=True),
        sa.Column("name", sa.String(length=200), nullable=True),
        sa.Column("lon", sa.Float(), nullable=True),
        sa.Column("lat", sa.Float(), nullable=True),
        sa.Column("imported_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_assets")),
    )
    op.create_index("ix_assets_line_id_track_km", "assets", ["line_id", "track", "km"])


def downgrade() -> None:
    op.drop_index("ix_assets_line_id_track_km", table_name="assets")
    op.drop_table("assets")
