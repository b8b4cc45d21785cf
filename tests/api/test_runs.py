"""Runs: list filters and pagination, detail, delete (rows and files)."""

from __future__ import annotations

import pytest
from sqlalchemy import func, select

from app.db.models import Job, Run
from app.db.session import Database
from tests.api import runfiles
from tests.api.support import store_files

RUNS = [
    # vehicle, line, start time
    ("ICE-1", "4010", "2026-01-10T08:00:00+01:00"),
    ("ICE-1", "4010", "2026-02-10T08:00:00+01:00"),
    ("ICE-2", "4010", "2026-02-11T23:30:00-01:00"),  # 2026-02-12 00:30 UTC
    ("ICE-2", "5100", "2026-03-01T12:00:00+00:00"),
]


@pytest.fixture
def populated(client, tmp_path):
    ids = []
    for i, (vehicle, line, start) in enumerate(RUNS):
        md = runfiles.metadata(
            vehicle_id=vehicle, line_id=line, start_time=start, sample_rate_hz=None
        )
        path = runfiles.write_hdf5(tmp_path / f"r{i}.h5", runfiles.channels(10_000, seed=i), md)
        with open(path, "rb") as fh:
            r = client.post("/api/v1/runs", files={"file": (path.name, fh)})
        assert r.status_code == 201, r.text
        ids.append(r.json()["id"])
    return ids


def _ids(client, **params):
    r = client.get("/api/v1/runs", params=params)
    assert r.status_code == 200, r.text
    return [item["id"] for item in r.json()["items"]], r.json()["total"]


def test_list_filters(client, populated):
    a, b, c, d = populated
    assert _ids(client) == ([d, c, b, a], 4)  # newest start first
    assert _ids(client, line_id="4010") == ([c, b, a], 3)
    assert _ids(client, vehicle_id="ICE-2") == ([d, c], 2)
    assert _ids(client, vehicle_id="ICE-2", line_id="4010") == ([c], 1)
    assert _ids(client, date_from="2026-02-01", date_to="2026-02-11") == ([b], 1)
    assert _ids(client, date_from="2026-02-12") == ([d, c], 2)
    assert _ids(client, date_to="2026-02-10T07:00:00Z") == ([b, a], 2)
    assert _ids(client, line_id="nope") == ([], 0)


def test_pagination(client, populated):
    page1, total = _ids(client, limit=3, offset=0)
    page2, _ = _ids(client, limit=3, offset=3)
    assert total == 4 and len(page1) == 3 and len(page2) == 1
    assert set(page1) | set(page2) == set(populated)


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"date_from": "yesterday"}, "date_from"),
        ({"date_from": "2026-03-01", "date_to": "2026-02-01"}, "date_from"),
        ({"limit": 100000}, "limit"),
    ],
)
def test_list_rejects_bad_parameters(client, params, field):
    r = client.get("/api/v1/runs", params=params)
    assert r.status_code == 422
    assert r.json()["field"] == field


def test_detail_and_missing(client, populated):
    run_id = populated[0]
    r = client.get(f"/api/v1/runs/{run_id}")
    assert r.status_code == 200
    body = r.json()
    assert body["metadata"]["vehicle_id"] == "ICE-1"
    assert len(body["sha256"]) == 64
    assert body["summary"]["channels"][:4] == ["Z11", "Z12", "Z41", "Z42"]
    # speeds answered in km/h (the file holds 20 m/s)
    assert body["summary"]["speed_min_kmh"] == pytest.approx(72.0) == body["summary"]["speed_max_kmh"]
    assert body["latest_job"]["status"] == "queued"
    assert client.get("/api/v1/runs/999").status_code == 404
    assert client.get("/api/v1/runs/0").status_code == 422
    assert client.get("/api/v1/runs/99999999999999999999").status_code == 422


def test_delete_removes_rows_and_files(client, populated):
    run_id = populated[1]
    run_dir = client.settings.run_store / str(run_id)
    assert (run_dir / "run.h5").is_file()
    assert client.delete(f"/api/v1/runs/{run_id}").status_code == 204
    assert not run_dir.exists()
    assert client.get(f"/api/v1/runs/{run_id}").status_code == 404
    assert client.delete(f"/api/v1/runs/{run_id}").status_code == 404
    db = Database(client.settings.database_url)
    try:
        with db.read() as s:
            assert s.scalar(select(func.count()).select_from(Run)) == 3
            assert s.scalar(select(func.count()).select_from(Job).where(Job.run_id == run_id)) == 0
    finally:
        db.dispose()
    assert len(store_files(client.settings.run_store)) == 3
    # ids are never reused: a new run gets a new directory
    path = runfiles.write_hdf5(client.settings.run_store.parent / "new.h5", runfiles.channels(10_000, seed=99))
    with open(path, "rb") as fh:
        new_id = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()["id"]
    assert new_id > max(populated)
