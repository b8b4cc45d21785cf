"""The demo data set processed once: a SQLite database and its run store shared by the golden
identity test (tests/e2e/test_refactor_identity.py) and the dashboard's browser tests.

:func:`build_processed_demo` uploads the demo's four runs, its reference data and both lines'
geometry through the API (in-process app), registers one webhook (so that the alerts outbox is
written too) and processes the jobs with the local worker one after the other, in upload order
(the order the change tests see their history in). The ``processed_demo`` fixture keeps the result
as a cached data set (tests/datasets.py); every user works on its own copy
(:meth:`ProcessedDemo.copy_to`), so no test sees another's changes.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

__all__ = ["DB_FILE", "RUN_STORE", "WEBHOOK_URL", "ProcessedDemo", "build_processed_demo"]

#: the database file and the run store in the data set's directory
DB_FILE, RUN_STORE = "db.sqlite", "runs"
#: a receiver that is never called (no delivery loop runs while the demo is processed): its outbox
#: rows are what counts
WEBHOOK_URL = "https://93.184.215.14/trackvkf-alerts"


@dataclass(frozen=True)
class ProcessedDemo:
    """The processed demo: its directory and the ids of what was uploaded, in upload order."""

    directory: Path
    run_ids: tuple[int, ...]
    job_ids: tuple[int, ...]
    geometry_ids: tuple[int, ...]
    webhook_id: int

    def copy_to(self, target: Path) -> tuple[str, Path]:
        """Copy the database and run store to ``target`` (created); (database URL, run store) of the copy."""
        target.mkdir(parents=True, exist_ok=True)
        shutil.copy2(self.directory / DB_FILE, target / DB_FILE)
        shutil.copytree(self.directory / RUN_STORE, target / RUN_STORE)
        return f"sqlite:///{target / DB_FILE}", target / RUN_STORE


def build_processed_demo(root: Path, demo) -> ProcessedDemo:
    """Upload ``demo`` (:class:`app.simulate.demo.DemoDataset`) into a new database in ``root`` and
    process it (module docstring)."""
    from fastapi.testclient import TestClient

    from app.db import migrate
    from app.db.session import Database
    from app.main import create_app
    from tests.api.support import auth_headers, create_api_key, make_settings
    from worker.runner import LocalWorker

    settings = make_settings(root, database_url=f"sqlite:///{root / DB_FILE}", run_store=root / RUN_STORE)
    migrate.upgrade(settings.database_url)
    key = create_api_key(settings.database_url, "admin", "identity")
    db = Database(settings.database_url)
    try:
        with TestClient(create_app(settings), headers=auth_headers(key)) as client:
            r = client.post("/api/v1/webhooks", json={"url": WEBHOOK_URL, "description": "identity test"})
            assert r.status_code == 201, r.text
            webhook_id = r.json()["id"]
            run_ids, job_ids = [], []
            for path in demo.runs:
                with open(path, "rb") as fh:
                    r = client.post("/api/v1/runs", files={"file": (path.name, fh, "application/x-hdf5")})
                assert r.status_code == 201, r.text
                run_ids.append(r.json()["id"])
                job_ids.append(r.json()["latest_job"]["id"])
            for kind, path in demo.reference.items():
                with open(path, "rb") as fh:
                    r = client.post(f"/api/v1/reference/{kind}", files={"file": (path.name, fh, "text/csv")})
                assert r.status_code == 201, r.text
            for path in demo.geometry:
                with open(path, "rb") as fh:
                    r = client.post("/api/v1/geometry", files={"file": (path.name, fh, "application/geo+json")})
                assert r.status_code in (200, 201), r.text
            worker = LocalWorker(settings, db=db, worker_id="identity-worker")
            assert worker.run(exit_when_idle=True) == len(run_ids)
            for job_id in job_ids:
                job = client.get(f"/api/v1/jobs/{job_id}").json()
                assert job["status"] == "done", job
            geometry_ids = [g["id"] for g in client.get("/api/v1/geometry").json()["items"]]
    finally:
        db.dispose()
    return ProcessedDemo(root, tuple(run_ids), tuple(job_ids), tuple(geometry_ids), webhook_id)
