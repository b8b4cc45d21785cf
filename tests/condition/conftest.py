"""Fixtures of the condition tests: the databases of tests/db (SQLite, and PostgreSQL where
the test cluster can be started)."""

import datetime as dt
from collections.abc import Iterator
from dataclasses import dataclass

import pytest

from app.simulate.fleet import FleetPlan, FleetSimulator, PlantedAction, PlantedStep, PlantedTrend
from app.simulate.track import generate_line
from tests.db.conftest import any_db, db  # noqa: F401  (fixtures)

#: the generated fleet of the API tests: line "F1" km 10–14, 60 daily runs from FLEET_START
FLEET_LINE, FLEET_RUNS = "F1", 60
FLEET_START = dt.datetime(2025, 3, 1, 8, 0, tzinfo=dt.UTC)
FLEET_PLAN = FleetPlan(
    steps=(PlantedStep(11_500.0, 11_520.0, day=45.0, factor=1.2),),
    trends=(PlantedTrend(12_300.0, 12_700.0, day=20.0, rate_per_year=0.5),),
    actions=(PlantedAction(13_000.0, 13_300.0, day=30.0, recovery=0.15, regrowth_per_year=0.3),),
)


@dataclass
class Fleet:
    """A test client on a database holding a generated fleet history."""

    client: object
    database_url: str
    plan: FleetPlan


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Iterator[Fleet]:
    """An API client (admin key) on a database with :data:`FLEET_RUNS` generated runs of line F1
    (and a second line "F2" on two tracks), written by :func:`app.condition.fleet.ingest_fleet`."""
    from fastapi.testclient import TestClient

    from app.condition.fleet import ingest_fleet
    from app.db import migrate
    from app.db.session import Database
    from app.main import create_app
    from tests.api.support import auth_headers, create_api_key, make_settings

    tmp = tmp_path_factory.mktemp("fleet")
    settings = make_settings(tmp)
    migrate.upgrade(settings.database_url)
    database = Database(settings.database_url)
    sim = FleetSimulator(generate_line(10_000.0, 14_000.0, seed=31), FLEET_PLAN)
    ingest_fleet(database, sim, FLEET_RUNS, line_id=FLEET_LINE, start=FLEET_START, seed=32)
    small = FleetSimulator(generate_line(0.0, 1_500.0, seed=33))
    for track in ("1", "2"):
        ingest_fleet(database, small, 3, line_id="F2", track=track, start=FLEET_START, seed=34, reference=False)
    database.dispose()
    key = create_api_key(settings.database_url, "viewer")
    with TestClient(create_app(settings), headers=auth_headers(key)) as client:
        yield Fleet(client, settings.database_url, FLEET_PLAN)
