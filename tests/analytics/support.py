"""Store a simulated, processed run through the API (upload) and the job queue."""

from __future__ import annotations

from app import publish
from app.db import queue
from app.db.session import Database


def store_run(client, run) -> int:
    """Upload ``run.path`` and complete its job with ``run.results``; returns the run id."""
    with open(run.path, "rb") as fh:
        r = client.post("/api/v1/runs", files={"file": (run.path.name, fh)})
    assert r.status_code in (200, 201), r.text
    body = r.json()
    db = Database(client.settings.database_url)
    try:
        job_id = queue.claim_next_job(db, "test", 30)
        assert job_id == body["latest_job"]["id"]
        res = run.results
        assert publish.publish_job(db, job_id, body["id"], res.profiles, res.wheels, res.meta, worker_id="test")
    finally:
        db.dispose()
    return body["id"]


def import_reference(client, files: dict[str, str]) -> None:
    """POST the simulated subsidence, maintenance and superstructure files."""
    for kind in ("subsidence", "maintenance", "superstructure"):
        with open(files[kind], "rb") as fh:
            r = client.post(f"/api/v1/reference/{kind}", files={"file": (files[kind].rsplit("/", 1)[-1], fh)})
        assert r.status_code == 201, r.text


def get(client, path: str, **params):
    """GET ``/api/v1{path}``, assert 200, return the JSON body."""
    r = client.get(f"/api/v1{path}", params=params)
    assert r.status_code == 200, r.text
    return r.json()
