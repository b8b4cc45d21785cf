"""Asset imports written in bounded batches and switched live per line and track: ``assets.import_id``,
``asset_imports`` (one row an import), ``asset_lines`` (the live import of each line and track).

The assets stored before become import 1, live on every line and track they are on.

Revision ID: 0023_asset_imports
Revises: 0022_condition_index
Create Date: 2026-11-28
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0023_asset_imports"
down_revision: str | None = "0022_condition_index"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "asset_imports",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("state", sa.String(length=16), nullable=False),
        sa.Column("n_rows", sa.Integer(), nullable=False),
        sa.Column("created_by", sa.String(length=128), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_asset_imports")),
        sqlite_autoincrement=True,
    )
    op.create_table(
        "asset_lines",
        sa.Column("line_id", sa.String(length=128), nullable=False),
        sa.Column("track", sa.String(length=64), nullable=False),
        sa.Column("import_id", sa.Integer(), nullable=False),
        sa.Column("n_assets", sa.Integer(), nullable=False),
        sa.Column("max_extent_km", sa.Float(), nullable=False),
        sa.PrimaryKeyConstraint("line_id", "track", name=op.f("pk_asset_lines")),
    )
    with op.batch_alter_table("assets") as batch:
        batch.add_column(sa.Column("import_id", sa.Integer(), nullable=False, server_default="1"))
    with op.batch_alter_table("assets") as batch:
        batch.alter_column("import_id", server_default=None)
    op.create_index("ix_assets_import_id", "assets", ["import_id"])
    if op.get_bind().execute(sa.text("SELECT count(*) FROM assets")).scalar():
        op.execute("INSERT INTO asset_imports (id, state, n_rows, created_by, created_at) "
                   "SELECT 1, 'live', count(*), NULL, CURRENT_TIMESTAMP FROM assets")
        op.execute("INSERT INTO asset_lines (line_id, track, import_id, n_assets, max_extent_km) "
                   "SELECT line_id, COALESCE(track, ''), 1, count(*), COALESCE(max(km_to - km), 0) "
                   "FROM assets GROUP BY line_id, COALESCE(track, '')")
        if op.get_bind().dialect.name == "postgresql":
            op.execute("SELECT setval(pg_get_serial_sequence('asset_imports', 'id'), 1)")


def downgrade() -> None:
    op.drop_index("ix_assets_import_id", table_name="assets")
    with op.batch_alter_table("assets") as batch:
        batch.drop_column("import_id")
    op.drop_table("asset_lines")
    op.drop_table("asset_imports")
