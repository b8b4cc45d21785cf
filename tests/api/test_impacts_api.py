"""Track impacts and wheel flats through the API: the profile column, the run's list of impacts, the
exports, and wheel flats with the run they were first seen in (stored results, real SQLite + HTTP client)."""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pytest

from app import publish
from app.db import queue
from app.db.session import Database
from tests.api import runfiles
from tests.profiles.test_profiles_api import _synthetic

FLAT = {"angle_deg": 57.7, "angle_spread_deg": 0.4, "depth_mm": 0.19, "length_mm": 40.0, "n_hits": 135,
        "n_revolutions": 135, "first_km": 12.5, "last_km": 12.99}


def _run(client, tmp_path, name: str, start: str, *, impacts: dict[float, float], flat_wheels: tuple[str, ...]):
    """Upload a run of vehicle ICE-1 and complete its job with synthetic results."""
    md = runfiles.metadata(sample_rate_hz=None, start_time=start)
    path = runfiles.write_hdf5(tmp_path / f"{name}.h5", runfiles.channels(10_000, seed=len(name)), md=md)
    with open(path, "rb") as fh:
        run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
    db = Database(client.settings.database_url)
    try:
        job_id = queue.claim_next_job(db, "test", 30)
        df, wheels = _synthetic()
        df["track_impact_mm"] = np.nan
        for km, depth in impacts.items():
            for wheel, shift in (("11", 0), ("12", 1), ("41", 0), ("42", 1)):  # wheels' bins differ a little
                b = int(np.floor(km * 1000 / 0.25)) + shift
                df.loc[(df.wheel == wheel) & (df.bin == b), "track_impact_mm"] = depth + (0.02 if wheel[1] == "2" else 0)
        for w in wheels:
            w["flat"] = dict(FLAT) if w["wheel"] in flat_wheels else None
        assert publish.publish_job(db, job_id, run["id"], df, wheels, {"software": "t"}, worker_id="test")
    finally:
        db.dispose()
    return run["id"], df


@pytest.fixture
def three_runs(client, tmp_path):
    first, _ = _run(client, tmp_path, "a", "2026-01-10T08:00:00+01:00", impacts={}, flat_wheels=())
    second, _ = _run(client, tmp_path, "bb", "2026-02-10T08:00:00+01:00", impacts={12.6: 0.3}, flat_wheels=("41",))
    third, df = _run(client, tmp_path, "ccc", "2026-03-10T08:00:00+01:00", impacts={12.6: 0.3, 12.8: 0.5},
                     flat_wheels=("41", "12"))
    return client, (first, second, third), df


def test_track_impacts_of_a_run(three_runs):
    client, (first, _, third), df = three_runs
    body = client.get(f"/api/v1/runs/{third}/track-impacts").json()
    assert [round(i["km"], 3) for i in body["items"]] == [12.6, 12.8]
    one = body["items"][1]
    assert one["wheels"] == ["11", "12", "41", "42"]
    assert one["depth_mm"] == pytest.approx(0.51) and one["depth_by_side_mm"] == pytest.approx({"1": 0.5, "2": 0.52})
    ranged = client.get(f"/api/v1/runs/{third}/track-impacts", params={"km_from": 12.7}).json()
    assert [round(i["km"], 3) for i in ranged["items"]] == [12.8]
    assert client.get(f"/api/v1/runs/{first}/track-impacts").json()["items"] == []
    assert client.get("/api/v1/runs/999/track-impacts").status_code == 404
    bad = client.get(f"/api/v1/runs/{third}/track-impacts", params={"km_from": "x"})
    assert bad.status_code == 422 and "km_from" in bad.text


def test_track_impact_column_in_profile_and_exports(three_runs):
    client, (_, _, third), df = three_runs
    rows = client.get(f"/api/v1/runs/{third}/profile",
                      params={"wheel": "11", "km_from": 12.59, "km_to": 12.61, "columns": "track_impact_mm"}).json()
    got = pd.DataFrame(rows["rows"])
    assert got["track_impact_mm"].notna().sum() == 1 and got["track_impact_mm"].max() == pytest.approx(0.3)
    agg = client.get(f"/api/v1/runs/{third}/profile", params={"wheel": "11", "level": 100}).json()
    maxima = [r["track_impact_mm_max"] for r in agg["rows"] if r["track_impact_mm_max"] is not None]
    assert sorted(maxima) == pytest.approx([0.3, 0.5])
    r = client.get(f"/api/v1/runs/{third}/profile.csv")
    assert r.status_code == 200, r.text
    exported = pd.read_csv(io.StringIO(r.text))
    assert "track_impact_mm" in exported.columns
    assert exported["track_impact_mm"].notna().sum() == df["track_impact_mm"].notna().sum() == 8
    parquet = pd.read_parquet(io.BytesIO(client.get(f"/api/v1/runs/{third}/profile.parquet").content))
    assert parquet["track_impact_mm"].notna().sum() == 8


def test_wheel_flats_with_first_seen(three_runs):
    client, (first, second, third), _ = three_runs
    items = {w["wheel"]: w for w in client.get(f"/api/v1/runs/{third}/wheels").json()["items"]}
    assert items["11"]["flat"] is None
    flat = items["41"]["flat"]
    assert flat["angle_deg"] == pytest.approx(57.7) and flat["depth_mm"] == pytest.approx(0.19)
    assert flat["first_seen_run_id"] == second  # seen in the second run already
    assert items["12"]["flat"]["first_seen_run_id"] == third
    assert client.get(f"/api/v1/runs/{first}/wheels").json()["items"][2]["flat"] is None
    now = client.get("/api/v1/wheels/flats", params={"vehicle_id": "ICE-1"}).json()
    assert [(i["wheel"], i["run_id"], i["flat"]["first_seen_run_id"]) for i in now["items"]] == [
        ("12", third, third), ("41", third, second)]
    assert client.get("/api/v1/wheels/flats", params={"vehicle_id": "nobody"}).json()["items"] == []
    assert client.get("/api/v1/wheels/flats").status_code == 422
    trend = client.get("/api/v1/wheels/trend", params={"vehicle_id": "ICE-1", "wheel": "41"}).json()
    assert [i["flat_depth_mm"] for i in trend["items"]] == [None, 0.19, 0.19]
