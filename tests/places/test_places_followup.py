"""The places follow-up of the publish step (issue 24, :mod:`app.places.followup`): a run's places are updated
after the publish commit, in transactions of their own, exactly once, in the order of the line's runs, and a
worker killed between the two commits loses nothing (real SQLite and PostgreSQL; a real process killed)."""

from __future__ import annotations

import datetime as dt
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import event, inspect, select, text

from app.db.models import (
    ConditionLine,
    ConditionRun,
    Job,
    PlaceObservation,
    PlaceRun,
    PlacesPending,
)
from app.places import followup
from app.simulate.fleet import FleetPlan, FleetSimulator, PlantedStep
from app.simulate.track import generate_line
from tests.condition.conftest import any_db, db  # noqa: F401  (fixtures)
from tests.condition.support import DAY0, publish_tracks

ROOT = Path(__file__).resolve().parents[2]
#: tables of the places and what in their rows is the time of the writing, not what was decided
PLACE_TABLES = ("places", "place_observations", "place_events", "place_actions", "place_runs",
                "place_status_history")
VOLATILE = {"created_at", "updated_at", "applied_at", "status_at", "at"}


def _sim() -> FleetSimulator:
    # a 1.5 km line with a step (softer by 25 %) over 30 m from day 2: places found, new and tier events
    return FleetSimulator(generate_line(12_000.0, 13_500.0, seed=7),
                          FleetPlan(steps=(PlantedStep(12_600.0, 12_630.0, day=2.0, factor=0.75),)), grid_m=0.25)


def _publish_days(database, days, *, followup_after: bool = True) -> list[tuple[int, int, dict]]:
    sim = _sim()
    out = []
    for day in days:
        _, tracks = sim.run(float(day), np.random.default_rng([5, day]))
        out.append(publish_tracks(database, tracks, DAY0 + dt.timedelta(days=day), followup=followup_after))
    return out


def _places_rows(database) -> dict[str, list[dict]]:
    insp = inspect(database.engine)
    out = {}
    with database.engine.connect() as conn:
        for table in PLACE_TABLES:
            keys = insp.get_pk_constraint(table)["constrained_columns"]
            rows = conn.execute(text(f"SELECT * FROM {table} ORDER BY {', '.join(keys)}")).mappings().all()
            out[table] = [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]
    return out


def test_the_follow_up_gives_the_places_of_the_in_transaction_update(any_db, tmp_path, request):  # noqa: F811
    """The same history published with the follow-up (after the commit) and with the update of before issue 24
    (update_places in a transaction that sees exactly the published run) gives the same places rows and
    job summaries."""
    from app.db import migrate
    from app.db.session import Database
    from app.places.update import update_places

    new = _publish_days(any_db, range(5))
    assert all(s["places"]["applied"] for _, _, s in new), [s["places"] for _, _, s in new]
    # the same backend (PostgreSQL stores the segment rows in single precision)
    url = f"sqlite:///{tmp_path / 'before.sqlite'}" if any_db.is_sqlite \
        else request.getfixturevalue("pg_cluster").create_database()
    migrate.upgrade(url)
    before = Database(url)
    try:
        old = []
        for run_id, job_id, summary in _publish_days(before, range(5), followup_after=False):
            assert summary["places"] == {"pending": True}
            with before.write() as s:
                cr = s.get(ConditionRun, run_id)
                up = update_places(s, run_id, s.get(ConditionLine, cr.line_key), job_id)
                s.delete(s.get(PlacesPending, run_id))
            old.append(up.summary())
        assert [s["places"] for _, _, s in new] == old
        got, want = _places_rows(any_db), _places_rows(before)
        assert got == want
        assert len(got["place_runs"]) == 5 and len(got["places"]) >= 1 and got["place_events"]
    finally:
        before.dispose()


def test_a_run_waits_for_the_earlier_pending_runs_of_its_line(any_db):  # noqa: F811
    (a, _, sa), (b, _, sb) = _publish_days(any_db, (0, 1), followup_after=False)
    assert sa["places"] == sb["places"] == {"pending": True}
    # b's follow-up alone (a worker that published b while a's places are pending): it waits for a
    assert followup.complete_run(any_db, b).outcome == "waiting"
    with any_db.read() as s:
        assert list(s.scalars(select(PlaceRun.run_id))) == []
        assert followup.due_runs(s) == [a]
        assert followup.due_runs(s, min_age_s=30.0) == []  # the loop leaves fresh runs to their publisher
        line_key = s.get(PlacesPending, a).line_key
        status = followup.line_places_status(s, line_key)
    assert status["places_pending"] == 2 and status["places_updated_at"] is None
    # the next publish of the line completes a, then b, then itself
    c, job_c, sc = _publish_days(any_db, (2,))[0]
    assert sc["places"]["applied"]
    with any_db.read() as s:
        applied = list(s.scalars(select(PlaceRun.run_id).order_by(PlaceRun.applied_at, PlaceRun.run_id)))
        assert applied == [a, b, c]
        assert s.scalar(select(PlacesPending.run_id)) is None
        for run_id in (a, b):
            job = s.scalar(select(Job).where(Job.run_id == run_id))
            assert job.meta["condition"]["places"]["applied"] is True
        status = followup.line_places_status(s, line_key)
    assert status["places_pending"] == 0 and status["places_run_id"] == c and status["places_updated_at"]


def test_the_work_list_says_how_current_the_places_are(db):  # noqa: F811
    from app.places.worklist import PlaceQuery, list_places

    (run_id, _, _), = _publish_days(db, (0,), followup_after=False)
    page = list_places(db, PlaceQuery(line_id="L1"))
    assert page["places_pending"] == 1 and page["places_updated_at"] is None and page["items"] == []
    assert page["lines"] == [{"line_id": "L1", "track": "1", "places_pending": 1, "places_failed": 0,
                              "places_run_id": None, "places_updated_at": None}]
    followup.run_pending(db)
    page = list_places(db, PlaceQuery(line_id="L1"))
    assert page["places_pending"] == 0 and page["places_updated_at"] is not None
    assert page["lines"][0]["places_run_id"] == run_id


def _transactions(database):
    """Record the statements of every transaction on ``database`` (kind ``write`` = BEGIN IMMEDIATE)."""
    log, open_ = [], {}

    def begin(conn):
        open_[id(conn)] = ("write" if conn.get_execution_options().get("sqlite_immediate") else "read", [])

    def statement(conn, cursor, sql, params, context, executemany):  # noqa: ARG001
        if id(conn) in open_:
            open_[id(conn)][1].append(sql)

    def end(conn):
        if id(conn) in open_:
            log.append(open_.pop(id(conn)))

    event.listen(database.engine, "begin", begin)
    event.listen(database.engine, "before_cursor_execute", statement)
    event.listen(database.engine, "commit", end)
    event.listen(database.engine, "rollback", end)
    return log


def test_the_publish_transaction_holds_no_places_statement_and_the_follow_up_writes_briefly(db):  # noqa: F811
    """Structure of the write lock on SQLite: the publish transaction writes the marker and no place row; the
    follow-up reads the store's rows in a read transaction and its write transaction reads none of them."""
    _publish_days(db, (0,))
    log = _transactions(db)
    (run_id, _, summary), = _publish_days(db, (1,))
    assert summary["places"]["applied"]
    writes = [sqls for kind, sqls in log if kind == "write"]
    publish = [sqls for sqls in writes if any("INSERT INTO places_pending" in q for q in sqls)]
    places = [sqls for sqls in writes if any("INSERT INTO place_runs" in q for q in sqls)]
    assert len(publish) == 1 and len(places) == 1
    assert not [q for q in publish[0] if any(f" {t} " in f" {q} " or f"{t}(" in q for t in PLACE_TABLES)
                and "places_pending" not in q]
    assert any("DELETE FROM places_pending" in q for q in places[0])
    assert not any("INSERT INTO places_pending" in q for q in places[0])
    assert not [q for q in places[0] if "segment_condition" in q]  # the store's rows: read without the lock
    reads = [sqls for kind, sqls in log if kind == "read" and any("segment_condition" in q for q in sqls)]
    assert reads, "the follow-up reads the store's rows in a read transaction"


#: publishes one run of the line and dies (SIGKILL, by itself) right after the publish commit, before the
#: places follow-up (where the follow-up would start)
_KILLED_AFTER_PUBLISH = """
import datetime as dt, os, signal, sys
import numpy as np
from app.db.session import Database
from app.places import followup
from tests.condition.support import DAY0, publish_tracks
from tests.places.test_places_followup import _sim
followup.complete_run = lambda *a, **k: os.kill(os.getpid(), signal.SIGKILL)
day = int(sys.argv[2])
_, tracks = _sim().run(float(day), np.random.default_rng([5, day]))
publish_tracks(Database(sys.argv[1]), tracks, DAY0 + dt.timedelta(days=day))
"""


@pytest.mark.timeout(300)
def test_a_worker_killed_between_the_publish_and_places_commits_loses_nothing(any_db, tmp_path):  # noqa: F811
    """A real process publishes and is killed before its places follow-up; the next worker's background
    (its start-up round of the places-followup loop) completes the places, once."""
    from tests.api.support import make_settings
    from worker.background import Background

    url = str(any_db.engine.url.render_as_string(hide_password=False))
    service_settings = make_settings(tmp_path, database_url=url)
    database = any_db
    env = {**{k: v for k, v in os.environ.items() if not k.startswith("TRACKVKF_")},
           "PYTHONPATH": str(ROOT)}
    for day in (0, 1):
        killed = subprocess.run([sys.executable, "-c", _KILLED_AFTER_PUBLISH, url, str(day)], env=env, cwd=ROOT,
                                capture_output=True, text=True, timeout=240)
        assert killed.returncode == -9, killed.stderr[-3000:]
    with database.read() as s:
        pending = list(s.scalars(select(PlacesPending.run_id).order_by(PlacesPending.run_time)))
        assert len(pending) == 2 and list(s.scalars(select(PlaceRun.run_id))) == []
        assert all(s.scalar(select(Job.status).where(Job.run_id == r)) == "done" for r in pending)

    # the runs were published seconds ago: no grace (their publisher died)
    background = Background(service_settings.model_copy(update={"places_followup_grace_s": 0.0}), "local").start()
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            with database.read() as s:
                if s.scalar(select(PlacesPending.run_id)) is None:
                    break
            time.sleep(0.2)
    finally:
        background.stop()
    assert followup.run_pending(database) == []  # nothing left, nothing done twice
    with database.read() as s:
        assert s.scalar(select(PlacesPending.run_id)) is None
        assert list(s.scalars(select(PlaceRun.run_id).order_by(PlaceRun.applied_at, PlaceRun.run_id))) == pending
        obs = s.execute(select(PlaceObservation.place_id, PlaceObservation.run_id)).all()
        assert obs and len(obs) == len(set(obs))
        for r in pending:
            assert s.scalar(select(Job.meta).where(Job.run_id == r))["condition"]["places"]["applied"] is True


def test_pending_places_updates_are_on_the_metrics(db, service_settings):  # noqa: F811
    from app.observability.metrics import DatabaseCollector

    def gauges() -> dict:
        out = {}
        for family in DatabaseCollector(db, service_settings, cache_s=0.0)._read():
            if family.name.startswith("trackvkf_places_pending"):
                out.update({(family.name, tuple(sorted(smp.labels.items()))): smp.value for smp in family.samples})
        return out

    _publish_days(db, (0,), followup_after=False)
    got = gauges()
    assert got[("trackvkf_places_pending", (("state", "waiting"),))] == 1
    assert got[("trackvkf_places_pending", (("state", "retrying"),))] == 0
    assert got[("trackvkf_places_pending_oldest_age_seconds", ())] >= 0
    followup.run_pending(db)
    got = gauges()
    assert got[("trackvkf_places_pending", (("state", "waiting"),))] == 0
    assert got[("trackvkf_places_pending_oldest_age_seconds", ())] == 0


def test_apply_places_completes_the_pending_runs_in_their_order(db):  # noqa: F811
    """``trackvkf apply-places`` (apply_stored_runs) takes a run whose places are pending through its follow-up:
    marker gone, the job's summary set, in the order of the line's runs."""
    from app.places.followup import apply_stored_runs

    runs = _publish_days(db, (0, 1, 2), followup_after=False)
    ups = apply_stored_runs(db, "L1", "1")
    assert [u.applied for u in ups] == [True, True, True]
    with db.read() as s:
        assert s.scalar(select(PlacesPending.run_id)) is None
        assert list(s.scalars(select(PlaceRun.run_id).order_by(PlaceRun.run_time))) == [r for r, _, _ in runs]
        assert all(s.get(Job, j).meta["condition"]["places"]["applied"] for _, j, _ in runs)
    assert apply_stored_runs(db, "L1", "1") == []
