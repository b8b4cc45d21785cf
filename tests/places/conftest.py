"""Fixtures of the places' service tests: a generated fleet history in the condition store (line "P1",
km 10–14, 30 runs two days apart: a −20 % step over 20 m on day 25, a trend, a tamping) of each
database backend (SQLite; PostgreSQL where the test cluster can be started), its first runs applied
to the line's places through the service, and API clients of each role."""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from dataclasses import dataclass, field

import pytest

from app.simulate.fleet import FleetPlan, PlantedAction, PlantedStep, PlantedTrend

LINE, N_RUNS, APPLIED, EVERY_DAYS = "P1", 30, 22, 2.0
START = dt.datetime(2025, 3, 1, 8, 0, tzinfo=dt.UTC)
STEP_FROM_M, STEP_TO_M, STEP_DAY = 11_500.0, 11_520.0, 25.0
PLAN = FleetPlan(
    steps=(PlantedStep(STEP_FROM_M, STEP_TO_M, day=STEP_DAY, factor=0.8),),
    trends=(PlantedTrend(12_300.0, 12_700.0, day=10.0, rate_per_year=0.5),),
    actions=(PlantedAction(13_000.0, 13_300.0, day=30.0, recovery=0.15, regrowth_per_year=0.3),),
)


@dataclass
class PlacesFleet:
    """A database with the fleet history, the first :data:`APPLIED` runs applied to the places."""

    backend: str
    database_url: str
    db: object
    clients: dict = field(default_factory=dict)
    run_ids: list = field(default_factory=list)


def _ingest(url: str) -> list[int]:
    from sqlalchemy import select

    from app.condition.fleet import ingest_fleet
    from app.db.models import ConditionRun
    from app.db.session import Database
    from app.simulate.fleet import FleetSimulator
    from app.simulate.track import generate_line

    db = Database(url)
    try:
        sim = FleetSimulator(generate_line(10_000.0, 14_000.0, seed=31), PLAN)
        ingest_fleet(db, sim, N_RUNS, line_id=LINE, start=START, every_days=EVERY_DAYS, seed=32)
        with db.read() as s:
            return [int(r) for r in s.scalars(select(ConditionRun.run_id).order_by(ConditionRun.run_time))]
    finally:
        db.dispose()


def apply_runs(db, run_ids, *, alerts: bool = False) -> list:
    """Apply runs (in order) to the line's places through the service, one transaction each."""
    from sqlalchemy import select

    from app.db.models import ConditionLine, ConditionRun
    from app.places.update import update_places

    out = []
    for rid in run_ids:
        with db.write() as s:
            cr = s.get(ConditionRun, rid)
            line = s.scalar(select(ConditionLine).where(ConditionLine.id == cr.line_key))
            out.append(update_places(s, rid, line, cr.job_id, alerts=alerts))
    return out


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def places_fleet(request, tmp_path_factory) -> Iterator[PlacesFleet]:
    from fastapi.testclient import TestClient

    from app.db import migrate
    from app.db.session import Database
    from app.main import create_app
    from tests.api.support import auth_headers, create_api_key, make_settings

    tmp = tmp_path_factory.mktemp(f"places-{request.param}")
    if request.param == "sqlite":
        settings = make_settings(tmp)
    else:
        cluster = request.getfixturevalue("pg_cluster")
        if isinstance(cluster, str):
            pytest.skip(cluster)
        settings = make_settings(tmp, database_url=cluster.create_database())
    url = settings.database_url
    migrate.upgrade(url)
    run_ids = _ingest(url)
    db = Database(url)
    ups = apply_runs(db, run_ids[:APPLIED])
    assert all(u.applied for u in ups), [u.summary() for u in ups if not u.applied]
    fleet = PlacesFleet(request.param, url, db, run_ids=run_ids)
    apps = []
    try:
        for role in ("viewer", "engineer", "admin"):
            key = create_api_key(url, role, name=f"{role}-key")
            c = TestClient(create_app(settings), headers=auth_headers(key))
            c.__enter__()
            apps.append(c)
            fleet.clients[role] = c
        yield fleet
    finally:
        for c in apps:
            c.__exit__(None, None, None)
        db.dispose()
