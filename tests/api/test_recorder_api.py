"""Channel maps, line geometry and recorder uploads over REST (MDF4/TDMS written in the test)."""

from __future__ import annotations

import copy
import json

import pytest
from sqlalchemy import func, select

from app.db.models import AuditEntry, Job, LineGeometryRow, Run
from app.db.session import Database
from app.simulate.recorder import GnssSimulation, simulate_recorder_run
from tests.api.support import store_files


@pytest.fixture(scope="module")
def recorder(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    return simulate_recorder_run(d / "run.mf4", "mdf4", gnss=GnssSimulation(), length_km=6,
                                 fs=2000.0, seed=7, with_forces=False, vehicle_id="ICE-9",
                                 line_id="4010")


def _count(settings, model) -> int:
    db = Database(settings.database_url)
    try:
        with db.read() as s:
            return int(s.scalar(select(func.count()).select_from(model)))
    finally:
        db.dispose()


def _actions(settings) -> list[str]:
    db = Database(settings.database_url)
    try:
        with db.read() as s:
            return [a for (a,) in s.execute(select(AuditEntry.action).order_by(AuditEntry.id))]
    finally:
        db.dispose()


def _upload(client, rec, **data):
    form = {"metadata": json.dumps(rec.metadata), **data}
    with open(rec.path, "rb") as fh:
        return client.post("/api/v1/runs", files={"file": (rec.path.name, fh, "application/octet-stream")},
                           data=form)


def _import_geometry(client, doc):
    return client.post("/api/v1/geometry",
                       files={"file": ("line.geojson", json.dumps(doc).encode(), "application/geo+json")})


def test_channel_map_crud_roles_and_audit(make_client, recorder):
    client = make_client()
    body = {"vehicle_id": "ICE-9", "name": "ipetronik", "channels": recorder.channel_map["channels"]}
    r = client.post("/api/v1/channel-maps", json=body)
    assert r.status_code == 201, r.text
    map_id = r.json()["id"]
    assert r.json()["channels"]["Z11"] == {"source": "AccZ_1R", "unit": "g"}
    assert client.post("/api/v1/channel-maps", json=body).status_code == 409
    bad = copy.deepcopy(body)
    bad["name"] = "bad"
    bad["channels"]["Z11"] = {"source": "AccZ_1R", "unit": "furlong"}
    r = client.post("/api/v1/channel-maps", json=bad)
    assert r.status_code == 422 and r.json()["field"] == "channel_map.channels"
    r = client.get("/api/v1/channel-maps", params={"vehicle_id": "ICE-9"})
    assert [m["id"] for m in r.json()["items"]] == [map_id]
    body["name"] = "renamed"
    assert client.put(f"/api/v1/channel-maps/{map_id}", json=body).json()["name"] == "renamed"
    viewer = make_client(role="viewer")
    assert viewer.get(f"/api/v1/channel-maps/{map_id}").status_code == 200
    assert viewer.delete(f"/api/v1/channel-maps/{map_id}").status_code == 403
    assert client.delete(f"/api/v1/channel-maps/{map_id}").status_code == 204
    assert client.get(f"/api/v1/channel-maps/{map_id}").status_code == 404
    acts = _actions(client.settings)
    assert {"channel_map.create", "channel_map.update", "channel_map.delete"} <= set(acts)


def test_geometry_import_errors_store_nothing(client, recorder):
    doc = json.loads(recorder.geometry_path.read_text())
    bad = copy.deepcopy(doc)
    bad["features"].append(copy.deepcopy(doc["features"][0]))
    bad["features"][1]["properties"]["track"] = "2"
    del bad["features"][1]["properties"]["km"]
    r = _import_geometry(client, bad)
    assert r.status_code == 422 and r.json()["field"] == "features[1]"
    assert "no km stations" in r.json()["detail"]
    assert _count(client.settings, LineGeometryRow) == 0
    r = _import_geometry(client, doc)
    assert r.status_code == 201, r.text
    (g,) = r.json()["imported"]
    assert g["line_id"] == "4010" and g["source_crs"] == "EPSG:25832"
    detail = client.get(f"/api/v1/geometry/{g['id']}").json()
    assert len(detail["lon"]) == g["n_vertices"] == len(detail["x_m"])
    assert "geometry.import" in _actions(client.settings)


def test_mdf4_gnss_upload_with_stored_map_and_geometry(client, recorder):
    r = _upload(client, recorder)  # no map: channel names are not trackvkf's
    assert r.status_code == 422 and r.json()["field"] == "channel_map"
    assert "AccZ_1R" in r.json()["detail"]
    map_id = client.post("/api/v1/channel-maps", json={
        "vehicle_id": "ICE-9", "name": "sim", "channels": recorder.channel_map["channels"]}).json()["id"]
    other = client.post("/api/v1/channel-maps", json={
        "vehicle_id": "ICE-1", "name": "sim", "channels": recorder.channel_map["channels"]}).json()["id"]
    r = _upload(client, recorder, channel_map=str(other))
    assert r.status_code == 422 and r.json()["field"] == "channel_map" and "ICE-1" in r.json()["detail"]
    r = _upload(client, recorder, channel_map=str(map_id))  # no geometry stored yet
    assert r.status_code == 422 and r.json()["field"] == "lat"
    assert (_count(client.settings, Run), _count(client.settings, Job)) == (0, 0)
    assert store_files(client.settings.run_store) == []

    far = json.loads(recorder.geometry_path.read_text())
    for p in far["features"][0]["geometry"]["coordinates"]:
        p[0] += 500.0  # 500 m east: every fix outside the 50 m corridor
    assert _import_geometry(client, far).status_code == 201
    r = _upload(client, recorder, channel_map=str(map_id))
    assert r.status_code == 422 and r.json()["field"] == "lat" and "more than 50 m" in r.json()["detail"]
    assert store_files(client.settings.run_store) == []

    assert _import_geometry(client, json.loads(recorder.geometry_path.read_text())).status_code == 201
    r = _upload(client, recorder, channel_map=str(map_id))
    assert r.status_code == 201, r.text
    run = r.json()
    assert run["source_format"] == "mdf4" and run["vehicle_id"] == "ICE-9"
    assert any("outage" in w for w in run["warnings"]) == bool(recorder.outages)
    assert run["ingest_report"]["km_source"] == "gnss"
    assert run["ingest_report"]["channels"]["speed"]["unit"] == "km/h"
    assert abs(run["km_start"] - recorder.truth.km_start) < 0.001
    listed = client.get("/api/v1/runs").json()["items"][0]
    assert listed["warnings"] == run["warnings"]


def test_recorder_upload_as_raw_body_with_query_channel_map(client, tmp_path):
    rec = simulate_recorder_run(tmp_path / "r.tdms", "tdms", gnss=None, length_km=1.0, fs=2000.0,
                                seed=3, with_forces=False, vehicle_id="V-2")
    map_id = client.post("/api/v1/channel-maps", json={
        "vehicle_id": "V-2", "name": "tdms", "channels": rec.channel_map["channels"]}).json()["id"]
    r = client.post("/api/v1/runs", content=rec.path.read_bytes(),
                    params={"filename": "r.tdms", "metadata": json.dumps(rec.metadata),
                            "channel_map": str(map_id)},
                    headers={"Content-Type": "application/octet-stream"})
    assert r.status_code == 201, r.text
    assert r.json()["source_format"] == "tdms"
    assert r.json()["ingest_report"]["km_source"] == "metadata"
    r = client.post("/api/v1/runs", content=b"x,y\n1,2\n", params={"filename": "a.csv", "channel_map": "abc"},
                    headers={"Content-Type": "text/csv"})
    assert r.status_code == 422 and r.json()["field"] == "channel_map"
