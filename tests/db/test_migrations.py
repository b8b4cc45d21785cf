"""Alembic migrations on SQLite: upgrade -> downgrade -> upgrade, and models match."""

from __future__ import annotations

from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import inspect

from app.db import migrate
from app.db.models import Base
from app.db.session import make_engine

TABLES = {
    "runs", "jobs", "job_chunks", "profile_bins", "wheel_oor",
    "users", "sessions", "api_keys", "audit_log",
    "ref_subsidence", "ref_maintenance", "ref_superstructure", "reference_curves",
    "condition_lines", "condition_runs", "segment_condition", "condition_flags",
    "webhooks", "webhook_deliveries", "condition_overview",
    "channel_maps", "line_geometries", "worker_heartbeats",
    "places", "place_observations", "place_events", "place_status_history", "place_actions", "place_runs",
    "assets", "places_pending", "asset_imports", "asset_lines",
}


def _tables(url: str) -> set[str]:
    engine = make_engine(url)
    try:
        return set(inspect(engine).get_table_names()) - {"alembic_version"}
    finally:
        engine.dispose()


def test_upgrade_downgrade_upgrade(tmp_path):
    url = f"sqlite:///{tmp_path / 'm.sqlite'}"
    migrate.upgrade(url)
    assert _tables(url) == TABLES
    head = migrate.current_revision(url)
    assert head == "0025_sleeper_step"  # one chain: the newest migration is the head

    migrate.downgrade(url, "base")
    assert _tables(url) == set()
    assert migrate.current_revision(url) is None

    migrate.upgrade(url)
    assert _tables(url) == TABLES
    assert migrate.current_revision(url) == head


def test_migrated_schema_matches_models(tmp_path):
    url = f"sqlite:///{tmp_path / 'm.sqlite'}"
    migrate.upgrade(url)
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            ctx = MigrationContext.configure(conn, opts={"compare_type": True})
            assert compare_metadata(ctx, Base.metadata) == []
    finally:
        engine.dispose()


def test_profile_bins_unique_and_indexed(tmp_path):
    url = f"sqlite:///{tmp_path / 'm.sqlite'}"
    migrate.upgrade(url)
    engine = make_engine(url)
    try:
        insp = inspect(engine)
        pk = insp.get_pk_constraint("profile_bins")["constrained_columns"]
        assert pk == ["job_id", "wheel", "bin"]  # rows by job: written beside the published ones
        indexes = {ix["name"]: ix for ix in insp.get_indexes("profile_bins")}
        # the primary key serves bin ranges; the impacts index holds only the bins with a track impact
        assert sorted(indexes) == ["ix_profile_bins_coarse_display", "ix_profile_bins_track_impacts"]
        assert "track_impact_mm IS NOT NULL" in str(indexes["ix_profile_bins_track_impacts"]["dialect_options"]
                                                    ["sqlite_where"])
        coarse = indexes["ix_profile_bins_coarse_display"]
        assert coarse["column_names"] == ["job_id", "wheel", "km", "display_level"]
        # partial: only the coarse display levels (storing ~10⁶ rows maintains 1/8 of an index)
        assert "display_level >= 2" in str(coarse["dialect_options"]["sqlite_where"])
        assert insp.get_foreign_keys("profile_bins") == []  # checked row by row: too slow for 10⁶ rows
        uniques = {tuple(u["column_names"]) for u in insp.get_unique_constraints("job_chunks")}
        assert ("job_id", "chunk_index") in uniques
        fks = {fk["referred_table"]: fk["options"] for fk in insp.get_foreign_keys("jobs")}
        assert fks["runs"].get("ondelete") == "CASCADE"
    finally:
        engine.dispose()


def test_display_levels_of_rows_stored_before_they_existed(tmp_path):
    """0005 ranks the rows already stored, as the service ranks new rows; down and up again."""
    import numpy as np
    import sqlalchemy as sa

    from app.analysis.aggregate import display_levels

    url = f"sqlite:///{tmp_path / 'm.sqlite'}"
    migrate.upgrade(url, "0004_procrastinate")
    rng = np.random.default_rng(1)
    amp = rng.lognormal(0, 0.4, 3000)
    amp[::97] = np.nan
    engine = sa.create_engine(url)  # no foreign-key enforcement: profile rows alone suffice here
    try:
        with engine.begin() as conn:
            conn.execute(
                sa.text("INSERT INTO profile_bins (run_id, job_id, wheel, bin, km, n_samples, sleeper_amp) "
                        "VALUES (:r, :j, :w, :b, :km, 10, :a)"),
                [{"r": r, "j": 10 + r, "w": w, "b": b, "km": 3 + b / 4000, "a": None if np.isnan(a) else float(a)}
                 for r in (1, 2) for w in ("11", "42") for b, a in enumerate(amp)],
            )
        migrate.upgrade(url)
        with engine.connect() as conn:
            for j, w in ((11, "11"), (12, "42")):
                got = conn.execute(
                    sa.text("SELECT display_level FROM profile_bins WHERE job_id = :j AND wheel = :w ORDER BY bin"),
                    {"j": j, "w": w},
                ).scalars().all()
                np.testing.assert_array_equal(got, display_levels(np.arange(amp.size), amp))
        migrate.downgrade(url, "0004_procrastinate")
        with engine.connect() as conn:
            assert conn.execute(sa.text("SELECT count(*) FROM profile_bins")).scalar() == 4 * amp.size
        migrate.upgrade(url)
        with engine.connect() as conn:
            assert conn.execute(sa.text("SELECT max(display_level) FROM profile_bins")).scalar() >= 5
    finally:
        engine.dispose()


def test_profile_rows_stored_before_the_step_estimate_keep_null(tmp_path):
    """0025 adds profile_bins.sleeper_step: rows of older jobs read NULL (no step estimate stored); down and
    up again keeps the rows."""
    import sqlalchemy as sa

    url = f"sqlite:///{tmp_path / 'm.sqlite'}"
    migrate.upgrade(url, "0024_user_language")
    engine = sa.create_engine(url)
    try:
        with engine.begin() as conn:
            conn.execute(sa.text("INSERT INTO profile_bins (run_id, job_id, wheel, bin, km, n_samples, sleeper_amp) "
                                 "VALUES (1, 1, '11', :b, :km, 10, 1.5)"), [{"b": b, "km": b / 4000} for b in range(5)])
        migrate.upgrade(url)
        with engine.connect() as conn:
            got = conn.execute(sa.text("SELECT sleeper_amp, sleeper_step FROM profile_bins ORDER BY bin")).all()
        assert got == [(1.5, None)] * 5
        migrate.downgrade(url, "0024_user_language")
        with engine.connect() as conn:
            cols = {c["name"] for c in sa.inspect(conn).get_columns("profile_bins")}
            assert "sleeper_step" not in cols
            assert conn.execute(sa.text("SELECT count(*) FROM profile_bins")).scalar() == 5
    finally:
        engine.dispose()
