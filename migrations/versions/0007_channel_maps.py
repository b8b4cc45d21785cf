"""Recorder input: channel_maps (per vehicle), line_geometries (per line and track), runs.ingest_report.

Revision ID: 0007_channel_maps
Revises: 0006_partial_display_index
Create Date: 2026-11-24
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op
from sqlalchemy.dialects import postgresql

revision: str = "0007_channel_maps"
down_revision: str | None = "0006_partial_display_index"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_JSON = sa.JSON().with_variant(postgresql.JSONB(astext_type=sa.Text()), "postgresql")


def upgrade() -> None:
    op.create_table(
        "channel_maps",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("vehicle_id", sa.String(length=128), nullable=False),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("channels", _JSON, nullable=False),
        sa.Column("created_by", sa.String(length=128), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("updated_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_channel_maps")),
        sa.UniqueConstraint("vehicle_id", "name", name=op.f("uq_channel_maps_vehicle_id_name")),
        sqlite_autoincrement=True,
    )
    op.create_index(op.f("ix_channel_maps_vehicle_id"), "channel_maps", ["vehicle_id"])
    op.create_table(
        "line_geometries",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("line_id", sa.String(length=128), nullable=False),
        sa.Column("track", sa.String(length=64), nullable=False),
        sa.Column("source_crs", sa.String(length=200), nullable=False),
        sa.Column("coordinates", _JSON, nullable=False),
        sa.Column("km", _JSON, nullable=False),
        sa.Column("length_m", sa.Float(), nullable=False),
        sa.Column("imported_by", sa.String(length=128), nullable=True),
        sa.Column("imported_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_line_geometries")),
        sa.UniqueConstraint("line_id", "track", name=op.f("uq_line_geometries_line_id_track")),
    )
    with op.batch_alter_table("runs") as batch:
        batch.add_column(sa.Column("ingest_report", _JSON, nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("runs") as batch:
        batch.drop_column("ingest_report")
    op.drop_table("line_geometries")
    op.drop_index(op.f("ix_channel_maps_vehicle_id"), table_name="channel_maps")
    op.drop_table("channel_maps")
