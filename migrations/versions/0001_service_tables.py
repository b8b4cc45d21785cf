"""Service tables: runs, jobs, job_chunks, profile_bins, wheel_oor.

Revision ID: 0001_service_tables
Revises:
Create Date: 2026-11-22
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op
from sqlalchemy.dialects import postgresql

revision: str = "0001_service_tables"
down_revision: str | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

ORDER_COLUMNS = [f"order_amp_{i:02d}" for i in range(1, 12)]

# Self-contained copies of the model types (migrations must not change when models do).
JSONType = sa.JSON().with_variant(postgresql.JSONB(), "postgresql")


def UTCDateTime() -> sa.DateTime:  # noqa: N802 - reads like the model type
    """Naive UTC timestamps (the models convert to and from aware UTC)."""
    return sa.DateTime()


def upgrade() -> None:
    op.create_table(
        "runs",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("sha256", sa.String(64), nullable=False),
        sa.Column("file_path", sa.String(255), nullable=False),
        sa.Column("source_format", sa.String(16), nullable=False),
        sa.Column("original_filename", sa.String(255), nullable=True),
        sa.Column("size_bytes", sa.BigInteger(), nullable=False),
        sa.Column("vehicle_id", sa.String(128), nullable=True),
        sa.Column("line_id", sa.String(128), nullable=True),
        sa.Column("track", sa.String(64), nullable=True),
        sa.Column("direction", sa.String(64), nullable=True),
        sa.Column("start_time", UTCDateTime(), nullable=True),
        sa.Column("km_start", sa.Float(), nullable=True),
        sa.Column("km_increasing", sa.Boolean(), nullable=True),
        sa.Column("fs", sa.Float(), nullable=False),
        sa.Column("n_samples", sa.BigInteger(), nullable=False),
        sa.Column("duration_s", sa.Float(), nullable=False),
        sa.Column("distance_m", sa.Float(), nullable=True),
        sa.Column("speed_min", sa.Float(), nullable=True),
        sa.Column("speed_max", sa.Float(), nullable=True),
        sa.Column("channels", JSONType, nullable=False),
        sa.Column("metadata", JSONType, nullable=False),
        sa.Column("created_by", sa.String(128), nullable=True),
        sa.Column("created_at", UTCDateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_runs"),
        sa.UniqueConstraint("sha256", name="uq_runs_sha256"),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_runs_vehicle_id", "runs", ["vehicle_id"])
    op.create_index("ix_runs_line_id", "runs", ["line_id"])
    op.create_index("ix_runs_start_time", "runs", ["start_time"])
    op.create_index("ix_runs_line_id_start_time", "runs", ["line_id", "start_time"])

    op.create_table(
        "jobs",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("progress", sa.Float(), nullable=False),
        sa.Column("error", sa.Text(), nullable=True),
        sa.Column("settings", JSONType, nullable=False),
        sa.Column("meta", JSONType, nullable=True),
        sa.Column("n_chunks", sa.Integer(), nullable=True),
        sa.Column("cancel_requested", sa.Boolean(), nullable=False),
        sa.Column("attempts", sa.Integer(), nullable=False),
        sa.Column("worker_id", sa.String(128), nullable=True),
        sa.Column("heartbeat_at", UTCDateTime(), nullable=True),
        sa.Column("created_by", sa.String(128), nullable=True),
        sa.Column("created_at", UTCDateTime(), nullable=False),
        sa.Column("started_at", UTCDateTime(), nullable=True),
        sa.Column("finished_at", UTCDateTime(), nullable=True),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name="fk_jobs_run_id_runs", ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name="pk_jobs"),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_jobs_run_id", "jobs", ["run_id"])
    op.create_index("ix_jobs_status_created_at", "jobs", ["status", "created_at"])

    op.create_table(
        "job_chunks",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("job_id", sa.Integer(), nullable=False),
        sa.Column("chunk_index", sa.Integer(), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("spec", JSONType, nullable=False),
        sa.Column("result_path", sa.String(512), nullable=True),
        sa.Column("started_at", UTCDateTime(), nullable=True),
        sa.Column("finished_at", UTCDateTime(), nullable=True),
        sa.ForeignKeyConstraint(
            ["job_id"], ["jobs.id"], name="fk_job_chunks_job_id_jobs", ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name="pk_job_chunks"),
        sa.UniqueConstraint("job_id", "chunk_index", name="uq_job_chunks_job_id_chunk_index"),
    )
    op.create_index("ix_job_chunks_job_id", "job_chunks", ["job_id"])

    op.create_table(
        "profile_bins",
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("wheel", sa.String(8), nullable=False),
        sa.Column("bin", sa.BigInteger(), autoincrement=False, nullable=False),
        sa.Column("job_id", sa.Integer(), nullable=True),
        sa.Column("km", sa.Float(), nullable=False),
        sa.Column("n_samples", sa.Integer(), nullable=False),
        sa.Column("speed_mean", sa.Float(), nullable=True),
        sa.Column("sleeper_amp", sa.Float(), nullable=True),
        *[sa.Column(name, sa.Float(), nullable=True) for name in ORDER_COLUMNS],
        sa.Column("residual_rms", sa.Float(), nullable=True),
        sa.Column("sleeper_force_amp", sa.Float(), nullable=True),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name="fk_profile_bins_run_id_runs", ondelete="CASCADE"
        ),
        sa.ForeignKeyConstraint(
            ["job_id"], ["jobs.id"], name="fk_profile_bins_job_id_jobs", ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("run_id", "wheel", "bin", name="pk_profile_bins"),
    )
    op.create_index("ix_profile_bins_job_id", "profile_bins", ["job_id"])
    op.create_index("ix_profile_bins_run_id_wheel_km", "profile_bins", ["run_id", "wheel", "km"])

    op.create_table(
        "wheel_oor",
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("wheel", sa.String(8), nullable=False),
        sa.Column("job_id", sa.Integer(), nullable=True),
        sa.Column("wheel_diameter_m", sa.Float(), nullable=True),
        sa.Column("n_windows", sa.Integer(), nullable=True),
        sa.Column("orders", JSONType, nullable=False),
        sa.Column("angles_deg", JSONType, nullable=False),
        sa.Column("profile_um", JSONType, nullable=False),
        sa.Column("profile_p05_um", JSONType, nullable=True),
        sa.Column("profile_p95_um", JSONType, nullable=True),
        sa.Column("extra", JSONType, nullable=True),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name="fk_wheel_oor_run_id_runs", ondelete="CASCADE"
        ),
        sa.ForeignKeyConstraint(
            ["job_id"], ["jobs.id"], name="fk_wheel_oor_job_id_jobs", ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("run_id", "wheel", name="pk_wheel_oor"),
    )
    op.create_index("ix_wheel_oor_job_id", "wheel_oor", ["job_id"])


def downgrade() -> None:
    op.drop_index("ix_wheel_oor_job_id", table_name="wheel_oor")
    op.drop_table("wheel_oor")
    op.drop_index("ix_profile_bins_run_id_wheel_km", table_name="profile_bins")
    op.drop_index("ix_profile_bins_job_id", table_name="profile_bins")
    op.drop_table("profile_bins")
    op.drop_index("ix_job_chunks_job_id", table_name="job_chunks")
    op.drop_table("job_chunks")
    op.drop_index("ix_jobs_status_created_at", table_name="jobs")
    op.drop_index("ix_jobs_run_id", table_name="jobs")
    op.drop_table("jobs")
    op.drop_index("ix_runs_line_id_start_time", table_name="runs")
    op.drop_index("ix_runs_start_time", table_name="runs")
    op.drop_index("ix_runs_line_id", table_name="runs")
    op.drop_index("ix_runs_vehicle_id", table_name="runs")
    op.drop_table("runs")
