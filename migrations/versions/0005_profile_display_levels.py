"""profile_bins: rows keyed by job, display levels, no row-by-row foreign keys.

* Primary key ``(job_id, wheel, bin)`` instead of ``(run_id, wheel, bin)``:
  a job's rows are written wheel by wheel (in parallel on several workers)
  beside the previous job's, and published by marking the job done
  (readers use the run's latest done job).
* ``display_level`` (min–max pyramid rank of every bin, see
  :func:`app.analysis.aggregate.display_levels`) and one covering index
  ``(job_id, wheel, km, display_level)`` instead of ``(run_id, wheel, km)``:
  a plot of a 100 km run reads a few thousand rows instead of 400 000 per
  wheel. Existing rows are ranked here.
* The foreign keys of ``profile_bins`` (and the ``job_id`` index that only
  served one of them) are dropped: PostgreSQL checks them row by row, which
  tripled the time to store a run's ~10⁶ rows. The service keeps the rows
  tied to their run (``app.db.results_writer.lock_run_for_results`` / ``delete_run``).

Revision ID: 0005_profile_display_levels
Revises: 0004_procrastinate
Create Date: 2026-11-22
"""

from collections.abc import Sequence

import numpy as np
import sqlalchemy as sa
from alembic import op

revision: str = "0005_profile_display_levels"
down_revision: str | None = "0004_procrastinate"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_UPDATE_BATCH = 20_000


def _rank_existing_rows() -> None:
    """Set ``display_level`` of the rows already stored, one (job, wheel) at a time."""
    conn = op.get_bind()
    profiles = conn.execute(sa.text("SELECT DISTINCT job_id, wheel FROM profile_bins")).all()
    if not profiles:  # a new database: nothing to rank (and the numerics stay unimported)
        return
    # the ranking is derived data (a cache of the amplitudes' order), not schema:
    # it comes from the same function the service uses when it stores new rows
    from app.analysis.aggregate import display_levels

    update = sa.text(
        "UPDATE profile_bins SET display_level = :level WHERE job_id = :job_id AND wheel = :wheel AND bin = :bin"
    )
    for job_id, wheel in profiles:
        rows = conn.execute(
            sa.text("SELECT bin, sleeper_amp FROM profile_bins WHERE job_id = :j AND wheel = :w"),
            {"j": job_id, "w": wheel},
        ).all()
        bins = np.array([r[0] for r in rows], dtype=np.int64)
        amp = np.array([np.nan if r[1] is None else r[1] for r in rows], dtype=np.float64)
        levels = display_levels(bins, amp)
        ranked = np.flatnonzero(levels > 0)
        for a in range(0, ranked.size, _UPDATE_BATCH):
            part = ranked[a : a + _UPDATE_BATCH]
            conn.execute(
                update,
                [{"level": int(levels[i]), "job_id": job_id, "wheel": wheel, "bin": int(bins[i])} for i in part],
            )


def upgrade() -> None:
    op.execute("DELETE FROM profile_bins WHERE job_id IS NULL")  # rows no reader could find
    with op.batch_alter_table("profile_bins", recreate="always") as batch:
        batch.drop_constraint("fk_profile_bins_run_id_runs", type_="foreignkey")
        batch.drop_constraint("fk_profile_bins_job_id_jobs", type_="foreignkey")
        batch.drop_index("ix_profile_bins_job_id")
        batch.drop_index("ix_profile_bins_run_id_wheel_km")
        batch.drop_constraint("pk_profile_bins", type_="primary")
        batch.alter_column("job_id", existing_type=sa.Integer(), nullable=False)
        batch.create_primary_key("pk_profile_bins", ["job_id", "wheel", "bin"])
        batch.add_column(sa.Column("display_level", sa.SmallInteger(), nullable=False, server_default="0"))
    _rank_existing_rows()
    op.create_index(
        "ix_profile_bins_job_id_wheel_km_level", "profile_bins", ["job_id", "wheel", "km", "display_level"]
    )


def downgrade() -> None:
    # back to one row per (run, wheel, bin): keep the latest job's rows of each run
    op.execute(
        "DELETE FROM profile_bins WHERE job_id <> "
        "(SELECT max(p.job_id) FROM profile_bins p WHERE p.run_id = profile_bins.run_id)"
    )
    op.drop_index("ix_profile_bins_job_id_wheel_km_level", table_name="profile_bins")
    with op.batch_alter_table("profile_bins", recreate="always") as batch:
        batch.drop_column("display_level")
        batch.drop_constraint("pk_profile_bins", type_="primary")
        batch.alter_column("job_id", existing_type=sa.Integer(), nullable=True)
        batch.create_primary_key("pk_profile_bins", ["run_id", "wheel", "bin"])
        batch.create_index("ix_profile_bins_job_id", ["job_id"])
        batch.create_index("ix_profile_bins_run_id_wheel_km", ["run_id", "wheel", "km"])
        batch.create_foreign_key(
            "fk_profile_bins_run_id_runs", "runs", ["run_id"], ["id"], ondelete="CASCADE"
        )
        batch.create_foreign_key(
            "fk_profile_bins_job_id_jobs", "jobs", ["job_id"], ["id"], ondelete="CASCADE"
        )
