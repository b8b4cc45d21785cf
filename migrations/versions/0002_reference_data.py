"""Reference data: ref_subsidence, ref_maintenance, ref_superstructure.

Revision ID: 0002_reference_data
Revises: 0001_service_tables
Create Date: 2026-11-22
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002_reference_data"
down_revision: str | None = "0001_service_tables"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "ref_subsidence",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("line_id", sa.String(length=128), nullable=False),
        sa.Column("track", sa.String(length=64), nullable=False),
        sa.Column("km", sa.Float(), nullable=False),
        sa.Column("rail", sa.SmallInteger(), nullable=True),
        sa.Column("subsidence_mm", sa.Float(), nullable=False),
        sa.Column("date", sa.Date(), nullable=False),
        sa.Column("imported_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_ref_subsidence")),
    )
    op.create_index("ix_ref_subsidence_line_id_track_km", "ref_subsidence", ["line_id", "track", "km"])
    op.create_table(
        "ref_maintenance",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("line_id", sa.String(length=128), nullable=False),
        sa.Column("track", sa.String(length=64), nullable=False),
        sa.Column("km_from", sa.Float(), nullable=False),
        sa.Column("km_to", sa.Float(), nullable=False),
        sa.Column("type", sa.String(length=32), nullable=False),
        sa.Column("date", sa.Date(), nullable=False),
        sa.Column("imported_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_ref_maintenance")),
    )
    op.create_index(
        "ix_ref_maintenance_line_id_track_km_from", "ref_maintenance", ["line_id", "track", "km_from"]
    )
    op.create_table(
        "ref_superstructure",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("line_id", sa.String(length=128), nullable=False),
        sa.Column("track", sa.String(length=64), nullable=False),
        sa.Column("km_from", sa.Float(), nullable=False),
        sa.Column("km_to", sa.Float(), nullable=False),
        sa.Column("type", sa.String(length=64), nullable=False),
        sa.Column("details", sa.Text(), nullable=True),
        sa.Column("imported_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_ref_superstructure")),
    )
    op.create_index(
        "ix_ref_superstructure_line_id_track_km_from", "ref_superstructure", ["line_id", "track", "km_from"]
    )


def downgrade() -> None:
    op.drop_index("ix_ref_superstructure_line_id_track_km_from", table_name="ref_superstructure")
    op.drop_table("ref_superstructure")
    op.drop_index("ix_ref_maintenance_line_id_track_km_from", table_name="ref_maintenance")
    op.drop_table("ref_maintenance")
    op.drop_index("ix_ref_subsidence_line_id_track_km", table_name="ref_subsidence")
    op.drop_table("ref_subsidence")
