"""Segment condition store: condition_lines, condition_runs, segment_condition, condition_overview,
condition_flags.

Rows are written when a job is published (the 25 cm profile rows stay the
source; these are kept for ever). Runs already processed get theirs when they
are reprocessed.

Revision ID: 0011_segment_condition
Revises: 0009_sleeper_harmonics
Create Date: 2026-11-24
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0011_segment_condition"
down_revision: str | None = "0010_reference_curves"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_FEED_ID = sa.BigInteger().with_variant(sa.Integer(), "sqlite")


def upgrade() -> None:
    op.create_table(
        "condition_lines",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("line_id", sa.String(length=128), nullable=False),
        sa.Column("track", sa.String(length=64), nullable=False),
        sa.Column("bin_length_m", sa.Float(), nullable=False),
        sa.Column("ref_run_id", sa.Integer(), nullable=True),
        sa.Column("ref_first_bin", sa.BigInteger(), nullable=True),
        sa.Column("ref_signature", sa.LargeBinary(), nullable=True),
        sa.Column("km_min", sa.Float(), nullable=True),
        sa.Column("km_max", sa.Float(), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_condition_lines")),
        sa.UniqueConstraint("line_id", "track", name=op.f("uq_condition_lines_line_id_track")),
        sqlite_autoincrement=True,
    )
    op.create_table(
        "condition_runs",
        sa.Column("run_id", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("line_key", sa.Integer(), nullable=False),
        sa.Column("job_id", sa.Integer(), nullable=False),
        sa.Column("run_time", sa.DateTime(), nullable=False),
        sa.Column("shift_m", sa.Float(), nullable=False),
        sa.Column("shift_confidence", sa.Float(), nullable=True),
        sa.Column("n_segments", sa.Integer(), nullable=False),
        sa.Column("n_flags", sa.Integer(), nullable=False),
        sa.Column("published_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("run_id", name=op.f("pk_condition_runs")),
    )
    op.create_index("ix_condition_runs_line_key_run_time", "condition_runs", ["line_key", "run_time"])
    op.create_table(
        "segment_condition",
        sa.Column("run_id", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("seg_m", sa.SmallInteger(), autoincrement=False, nullable=False),
        sa.Column("wheel", sa.String(length=8), nullable=False),
        sa.Column("seg", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("line_key", sa.Integer(), nullable=False),
        sa.Column("job_id", sa.Integer(), nullable=False),
        sa.Column("n_valid", sa.Integer(), nullable=False),
        sa.Column("amp_mean", sa.REAL(), nullable=False),
        sa.Column("amp_p95", sa.REAL(), nullable=False),
        sa.Column("speed_mean", sa.REAL(), nullable=False),
        sa.Column("index", sa.REAL(), nullable=False),
        sa.Column("index_sd", sa.REAL(), nullable=True),
        sa.Column("n_history", sa.SmallInteger(), nullable=False),
        sa.Column("baseline", sa.REAL(), nullable=True),
        sa.Column("change", sa.REAL(), nullable=True),
        sa.Column("change_z", sa.REAL(), nullable=True),
        sa.Column("trend_rate", sa.REAL(), nullable=True),
        sa.Column("trend_z", sa.REAL(), nullable=True),
        sa.PrimaryKeyConstraint("run_id", "seg_m", "wheel", "seg", name=op.f("pk_segment_condition")),
        sqlite_with_rowid=False,
    )
    op.create_index("ix_segment_condition_line_key_seg_m_seg", "segment_condition", ["line_key", "seg_m", "seg"])
    op.create_table(
        "condition_overview",
        sa.Column("run_id", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("seg", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("line_key", sa.Integer(), nullable=False),
        sa.Column("index", sa.REAL(), nullable=False),
        sa.Column("n_wheels", sa.SmallInteger(), nullable=False),
        sa.Column("flagged", sa.Boolean(), nullable=False),
        sa.PrimaryKeyConstraint("run_id", "seg", name=op.f("pk_condition_overview")),
    )
    op.create_table(
        "condition_flags",
        sa.Column("id", _FEED_ID, autoincrement=True, nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("line_key", sa.Integer(), nullable=False),
        sa.Column("job_id", sa.Integer(), nullable=False),
        sa.Column("seg_m", sa.SmallInteger(), nullable=False),
        sa.Column("seg", sa.Integer(), nullable=False),
        sa.Column("wheels", sa.String(length=32), nullable=False),
        sa.Column("n_wheels", sa.SmallInteger(), nullable=False),
        sa.Column("kind", sa.String(length=16), nullable=False),
        sa.Column("direction", sa.SmallInteger(), nullable=False),
        sa.Column("score", sa.Float(), nullable=False),
        sa.Column("change", sa.Float(), nullable=True),
        sa.Column("rate_per_year", sa.Float(), nullable=True),
        sa.Column("is_new", sa.Boolean(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_condition_flags")),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_condition_flags_run_id", "condition_flags", ["run_id"])
    op.create_index("ix_condition_flags_line_key_seg_m_seg", "condition_flags", ["line_key", "seg_m", "seg"])


def downgrade() -> None:
    op.drop_index("ix_condition_flags_line_key_seg_m_seg", table_name="condition_flags")
    op.drop_index("ix_condition_flags_run_id", table_name="condition_flags")
    op.drop_table("condition_flags")
    op.drop_table("condition_overview")
    op.drop_index("ix_segment_condition_line_key_seg_m_seg", table_name="segment_condition")
    op.drop_table("segment_condition")
    op.drop_index("ix_condition_runs_line_key_run_time", table_name="condition_runs")
    op.drop_table("condition_runs")
    op.drop_table("condition_lines")
