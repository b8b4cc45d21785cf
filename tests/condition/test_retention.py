"""Retention of the 25 cm rows: the sweep (both databases), 410 for swept runs, segment rows kept;
on PostgreSQL the partitioned profile table (rows of earlier versions attached, partitions dropped)."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from sqlalchemy import MetaData, Table, func, select, text

from app.db import migrate, partitions
from app.db.models import ProfileBin, Run, SegmentCondition
from app.db.retention import sweep_profiles
from app.db.session import Database
from app.simulate.fleet import FleetNoise, FleetSimulator
from app.simulate.track import generate_line
from tests.condition.support import publish_tracks
from tests.db.support import profile_table

SIM = FleetSimulator(generate_line(12_000.0, 13_000.0, seed=9), noise=FleetNoise(), grid_m=0.25)
NOW = dt.datetime.now(dt.UTC)


def _count(db: Database, table) -> int:
    with db.read() as s:
        return int(s.scalar(select(func.count()).select_from(table)))


def _runs(db: Database, ages_days: list[float]) -> list[int]:
    ids = []
    for i, age in enumerate(ages_days):
        _, tracks = SIM.run(float(i), np.random.default_rng(i))
        run_id, _, _ = publish_tracks(db, tracks, NOW - dt.timedelta(days=age))
        ids.append(run_id)
    return ids


def test_the_sweep_removes_old_profile_rows_and_keeps_the_condition(any_db):
    old, old2, new = _runs(any_db, [400, 200, 10])
    rows_before = _count(any_db, ProfileBin)
    segments_before = _count(any_db, SegmentCondition)
    dry = sweep_profiles(any_db, NOW - dt.timedelta(days=100), dry_run=True)
    assert dry.runs == 2 and _count(any_db, ProfileBin) == rows_before
    result = sweep_profiles(any_db, NOW - dt.timedelta(days=100))
    assert result.runs == 2
    with any_db.read() as s:
        left = {r: s.scalar(select(func.count()).select_from(ProfileBin).where(ProfileBin.run_id == r))
                for r in (old, old2, new)}
        swept = {r.id: r.profiles_swept_at for r in s.scalars(select(Run))}
    assert left[old] == left[old2] == 0 and left[new] == rows_before // 3
    assert swept[old] and swept[old2] and swept[new] is None
    assert _count(any_db, SegmentCondition) == segments_before  # segment rows are kept for ever
    assert sweep_profiles(any_db, NOW - dt.timedelta(days=100)).runs == 0  # nothing left to do
    _, tracks = SIM.run(5.0, np.random.default_rng(5))
    publish_tracks(any_db, tracks, NOW - dt.timedelta(days=400), run_id=old)  # reprocessed: rows again
    with any_db.read() as s:
        assert s.get(Run, old).profiles_swept_at is None


def test_a_swept_run_answers_410_with_where_the_condition_is(make_client):
    client = make_client()
    db = Database(client.settings.database_url)
    try:
        (old,) = _runs(db, [500])
        sweep_profiles(db, NOW - dt.timedelta(days=30))
    finally:
        db.dispose()
    r = client.get(f"/api/v1/runs/{old}/profile", params={"wheel": "11"})
    assert r.status_code == 410 and r.json()["field"] == "profile"
    assert "retention" in r.json()["detail"] and "/condition/" in r.json()["detail"]
    assert client.get(f"/api/v1/runs/{old}/profile.csv").status_code == 410
    assert client.get(f"/api/v1/condition/runs/{old}/changes").status_code == 200


def test_postgresql_profile_rows_are_partitioned_by_job_range(pg_cluster):
    if isinstance(pg_cluster, str):
        pytest.skip(pg_cluster)
    url = pg_cluster.create_database()
    migrate.upgrade(url, "0012_condition_webhooks")  # a database of the version before, with rows
    db = Database(url)
    try:
        with db.write() as s:  # the models know columns of later versions: plain SQL
            s.execute(text("INSERT INTO runs (sha256, file_path, source_format, size_bytes, fs, n_samples, duration_s, "
                           "channels, metadata, created_at) VALUES ('x', 'x', 'hdf5', 1, 1, 1, 1, '[]', '{}', now())"))
            run_id = s.execute(text("SELECT max(id) FROM runs")).scalar()
            s.execute(text("INSERT INTO jobs (run_id, status, progress, settings, cancel_requested, attempts, "
                           "created_at) VALUES (:r, 'done', 1, '{}', false, 1, now())"), {"r": run_id})
            job_id = s.execute(text("SELECT max(id) FROM jobs")).scalar()
        from app.db import results_writer

        with db.write() as s:  # the rows as the writer lays them out, less the columns of later versions
            table = Table("profile_bins", MetaData(), autoload_with=s.connection())
            frame = results_writer._profile_frame(profile_table(n_bins=300), run_id, job_id)
            rows = frame[[c.name for c in table.columns]].astype(object).where(frame.notna(), None)
            s.execute(table.insert(), rows.to_dict("records"))
        migrate.upgrade(url)
        with db.read() as s:
            parts = partitions.list_partitions(s)
            assert s.scalar(select(func.count()).select_from(ProfileBin)) == 600  # the rows stayed, attached
        names = {p.name: p for p in parts}
        assert names["profile_bins_legacy"].lo is None and names["profile_bins_legacy"].hi == 1000
        assert "profile_bins_default" in names and "profile_bins_j0000001000" in names
        # the legacy partition takes jobs up to 999; later ones get their partitions before their rows
        (young_legacy,) = _runs(db, [300])
        with db.write() as s:
            s.execute(text("SELECT setval('jobs_id_seq', 1499)"))
        (new_run,) = _runs(db, [5])
        with db.read() as s:
            where = dict(s.execute(text("SELECT run_id, tableoid::regclass::text FROM profile_bins GROUP BY 1, 2")).all())
            names = {p.name for p in partitions.list_partitions(s)}
        assert where == {run_id: "profile_bins_legacy", young_legacy: "profile_bins_legacy",
                         new_run: "profile_bins_j0000001000"}
        assert "profile_bins_j0000002000" in names  # the next range is made ahead
        with db.write() as s:
            s.execute(text("UPDATE runs SET start_time = now() - interval '2 years' WHERE id = :r"), {"r": run_id})
        kept = sweep_profiles(db, NOW - dt.timedelta(days=365))  # the legacy partition still holds a young run
        assert kept.runs == 1 and kept.partitions == [] and kept.rows == 600
        dropped = sweep_profiles(db, NOW - dt.timedelta(days=100))  # now all its runs are old: dropped whole
        assert dropped.runs == 1 and dropped.partitions == ["profile_bins_legacy"] and dropped.rows == 0
        with db.read() as s:
            assert s.scalar(select(func.count()).select_from(ProfileBin).where(ProfileBin.run_id != new_run)) == 0
            assert s.scalar(select(func.count()).select_from(ProfileBin).where(ProfileBin.run_id == new_run)) > 0
            assert "profile_bins_legacy" not in {p.name for p in partitions.list_partitions(s)}
        migrate.downgrade(url, "0012_condition_webhooks")  # back to one plain table, rows kept
        with db.read() as s:
            assert s.scalar(text("SELECT relkind FROM pg_class WHERE relname = 'profile_bins'")) == "r"
            assert s.scalar(select(func.count()).select_from(ProfileBin).where(ProfileBin.run_id == new_run)) > 0
        migrate.upgrade(url)
    finally:
        db.dispose()
