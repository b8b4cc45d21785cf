"""GET /condition/sections on a real SQLite store holding a generated year of runs: per 200 m section a
class from the speed-conditioned index of the 10 m rows, a lasting stiff section and a new one classed
E, healthy track A–C, the length per class now and a year before, and the bad-input answers."""

from __future__ import annotations

import datetime as dt

import pytest

LINE = "SEC"


@pytest.fixture(scope="module")
def sections_client(tmp_path_factory):
    from fastapi.testclient import TestClient

    from app.condition.fleet import ingest_fleet
    from app.db import migrate
    from app.db.session import Database
    from app.main import create_app
    from app.simulate.fleet import FleetPlan, FleetSimulator, PlantedStep
    from app.simulate.track import generate_line
    from tests.api.support import auth_headers, create_api_key, make_settings

    tmp = tmp_path_factory.mktemp("sections")
    settings = make_settings(tmp)
    migrate.upgrade(settings.database_url)
    plan = FleetPlan(steps=(PlantedStep(2_000.0, 2_200.0, day=0.0, factor=1.6),
                            PlantedStep(3_000.0, 3_200.0, day=200.0, factor=1.6)))
    sim = FleetSimulator(generate_line(0.0, 4_000.0, seed=5), plan)
    db = Database(settings.database_url)
    ingest_fleet(db, sim, 14, line_id=LINE, start=dt.datetime(2024, 1, 8, 8, 0, tzinfo=dt.UTC), every_days=30.0,
                 seed=6)
    db.dispose()
    key = create_api_key(settings.database_url, "viewer")
    with TestClient(create_app(settings), headers=auth_headers(key)) as client:
        yield client


def _cls(body: dict, km: float) -> str:
    return next(s["class"] for s in body["sections"] if s["km_from"] <= km < s["km_to"])


def test_sections_class_the_line_now_and_a_year_ago(sections_client):
    r = sections_client.get("/api/v1/condition/sections", params={"line_id": LINE})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["section_m"] == 200 and body["limits"] == [0.05, 0.10, 0.17, 0.25]
    assert "ln(A/A_ref(class, v))" in body["quantity"]
    secs = body["sections"]
    assert len(secs) >= 19 and all(s["class"] in ("A", "B", "C", "D", "E", "") for s in secs)
    assert _cls(body, 2.1) == "E" and _cls(body, 3.1) == "E"
    healthy = [s["class"] for s in secs if s["class"] and not (1.8 <= s["km_from"] < 2.4 or 2.8 <= s["km_from"] < 3.4)]
    assert healthy and sum(c in "ABC" for c in healthy) / len(healthy) >= 0.8, healthy
    e = [s for s in secs if s["class"] == "E"]
    assert all(s["rms"] >= 0.25 for s in e)
    total = sum(s["km_to"] - s["km_from"] for s in secs) * 1000
    assert sum(body["length_by_class"].values()) == pytest.approx(total)
    # a year before the newest run: the lasting section was E already, the new one was not
    old = body["length_by_class_year_ago"]
    assert old is not None and body["run_id_year_ago"] is not None
    assert body["length_by_class"]["E"] >= old["E"] + 200.0 - 1e-6
    r100 = sections_client.get("/api/v1/condition/sections", params={"line_id": LINE, "section_m": 100}).json()
    assert len(r100["sections"]) >= 2 * len(secs) - 2


def test_sections_bad_input(sections_client):
    r = sections_client.get("/api/v1/condition/sections", params={"line_id": "NOPE"})
    assert r.status_code == 404 and r.json()["field"] == "line_id"
    r = sections_client.get("/api/v1/condition/sections", params={"line_id": LINE, "section_m": 205})
    assert r.status_code == 422 and r.json()["field"] == "section_m"
    r = sections_client.get("/api/v1/condition/sections", params={"line_id": LINE, "section_m": 0})
    assert r.status_code == 422 and r.json()["field"] == "section_m"
