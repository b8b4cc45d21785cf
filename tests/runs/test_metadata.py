"""Re-uploads with other metadata (409) and the correction of a run's metadata (PATCH)."""

from __future__ import annotations

import json

from sqlalchemy import select

from app.db.models import AuditEntry, Job, Run
from app.db.session import Database
from tests.api import runfiles
from tests.api.support import store_files


def _post_csv(client, path, md):
    with open(path, "rb") as fh:
        return client.post("/api/v1/runs", files={"file": (path.name, fh, "text/csv")},
                           data={"metadata": json.dumps(md)})


def _finish_jobs(settings) -> None:
    """Mark the queued jobs done (no worker in these tests)."""
    db = Database(settings.database_url)
    try:
        with db.write() as s:
            for job in s.scalars(select(Job).where(Job.status.in_(("queued", "running")))):
                job.status = "done"
    finally:
        db.dispose()


def _rows(settings, model):
    db = Database(settings.database_url)
    try:
        with db.read() as s:
            return list(s.scalars(select(model).order_by(model.id)))
    finally:
        db.dispose()


def test_reupload_with_the_same_metadata_is_the_same_run(client, tmp_path):
    path = runfiles.write_csv(tmp_path / "run.csv")
    first = _post_csv(client, path, runfiles.metadata())
    assert first.status_code == 201, first.text
    # the same values written differently (km as a string, a date with the same instant)
    again = _post_csv(client, path, runfiles.metadata(km_start="12.5", start_time="2026-03-02T07:00:00Z"))
    assert again.status_code == 200, again.text
    assert again.json()["id"] == first.json()["id"]


def test_reupload_with_other_metadata_is_409_naming_the_fields(client, tmp_path):
    path = runfiles.write_csv(tmp_path / "run.csv")
    first = _post_csv(client, path, runfiles.metadata())
    run_id = first.json()["id"]
    r = _post_csv(client, path, runfiles.metadata(line_id="4020", km_start=13.0))
    assert r.status_code == 409, r.text
    body = r.json()
    assert body["field"] == "metadata"
    assert body["detail"].startswith(f"metadata: this file was uploaded before as run {run_id}")
    assert "line_id: '4010' stored, '4020' given" in body["detail"]
    assert "km_start: 12.5 stored, 13.0 given" in body["detail"]
    assert f"PATCH /api/v1/runs/{run_id}" in body["detail"]
    assert [run.line_id for run in _rows(client.settings, Run)] == ["4010"]  # nothing changed
    # an invalid value in the metadata of a duplicate is named like for a new file
    bad = _post_csv(client, path, runfiles.metadata(km_start="east"))
    assert bad.status_code == 422 and bad.json()["field"] == "km_start"


def test_patch_corrects_metadata_reingests_reprocesses_and_audits(client, tmp_path):
    path = runfiles.write_csv(tmp_path / "run.csv")
    run = _post_csv(client, path, runfiles.metadata()).json()
    run_id = run["id"]
    busy = client.patch(f"/api/v1/runs/{run_id}", json={"metadata": {"line_id": "4020"}})
    assert busy.status_code == 409 and busy.json()["field"] == "job"  # its first job is queued
    _finish_jobs(client.settings)

    r = client.patch(f"/api/v1/runs/{run_id}", json={"metadata": {"line_id": "4020", "km_start": 13.25,
                                                                  "vehicle_id": "ICE-1"}})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["line_id"] == "4020" and body["km_start"] == 13.25
    assert body["metadata"]["line_id"] == "4020"
    assert {c["field"]: (c["old"], c["new"]) for c in body["changed"]} == {
        "line_id": ("4010", "4020"), "km_start": (12.5, 13.25)}  # vehicle_id was already ICE-1
    assert body["reprocess_job_id"] == body["latest_job"]["id"] and body["latest_job"]["status"] == "queued"
    # the file was re-ingested into a new revision; the old one is gone
    files = [p.relative_to(client.settings.run_store).as_posix() for p in store_files(client.settings.run_store)]
    assert files == [f"{run_id}/run-r2.h5"]
    from app.io import open_run

    with open_run(client.settings.run_store / files[0]) as rf:
        assert rf.metadata.line_id == "4020" and rf.metadata.km_start == 13.25
    audit = [a for a in _rows(client.settings, AuditEntry) if a.action == "run.metadata"]
    assert len(audit) == 1 and audit[0].detail["changed"]["line_id"] == ["4010", "4020"]
    assert audit[0].detail["job_id"] == body["reprocess_job_id"]
    # the same file with the corrected metadata is now the same run
    _finish_jobs(client.settings)
    again = _post_csv(client, path, runfiles.metadata(line_id="4020", km_start=13.25))
    assert again.status_code == 200 and again.json()["id"] == run_id
    # nothing to change: no job
    same = client.patch(f"/api/v1/runs/{run_id}", json={"metadata": {"line_id": "4020"}})
    assert same.status_code == 200 and same.json()["changed"] == [] and same.json()["reprocess_job_id"] is None


def test_patch_rejects_bad_metadata_and_writes_nothing(client, tmp_path):
    path = runfiles.write_csv(tmp_path / "run.csv")
    run_id = _post_csv(client, path, runfiles.metadata()).json()["id"]
    _finish_jobs(client.settings)
    for payload, field in (({"metadata": {"km_start": "east"}}, "km_start"),
                           ({"metadata": {}}, "metadata"), ({"line_id": "4020"}, "line_id")):
        r = client.patch(f"/api/v1/runs/{run_id}", json=payload)
        assert r.status_code == 422, r.text
        assert field in str(r.json()["detail"]), r.json()
    assert [p.name for p in store_files(client.settings.run_store)] == ["run.h5"]
    assert client.patch("/api/v1/runs/999", json={"metadata": {"line_id": "x"}}).status_code == 404
