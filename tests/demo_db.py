"""The demo data set processed once: a SQLite database and its run store shared by the golden
identity test (tests/e2e/test_refactor_identity.py) and the dashboard's browser tests; and the
demo's history (``write_demo_dataset(history=True)``, what ``trackvkf demo`` uploads) processed once
for the Condition page's tests (:func:`processed_history`).

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

__all__ = ["DB_FILE", "RUN_STORE", "WEBHOOK_URL", "ProcessedDemo", "ProcessedHistory", "build_processed_demo",
           "build_processed_history", "processed_history"]

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
        return _copy(self.directory, target)


def _copy(directory: Path, target: Path) -> tuple[str, Path]:
    target.mkdir(parents=True, exist_ok=True)
    shutil.copy2(directory / DB_FILE, target / DB_FILE)
    shutil.copytree(directory / RUN_STORE, target / RUN_STORE)
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


@dataclass(frozen=True)
class ProcessedHistory:
    """The demo's history processed: its directory, its files (``data``: the history's spec, reference
    data, assets, geometry, runs), the ids of the history's runs in date order, and the demo's runs of
    the other lines (``rest``: not processed here, for the user to upload through its service)."""

    directory: Path
    data: object
    run_ids: tuple[int, ...]
    rest: tuple[Path, ...]

    def copy_to(self, target: Path) -> tuple[str, Path]:
        """Copy the database and run store to ``target`` (created); (database URL, run store) of the copy."""
        return _copy(self.directory, target)


def build_processed_history(root: Path, data) -> ProcessedHistory:
    """Import the reference data, the lines' geometry and the assets of ``data`` (a
    :class:`app.simulate.demo.DemoDataset` written with ``history=True``) into a new database in
    ``root`` through the API (in-process app), then upload the history's runs one after the other,
    each processed by the local worker and its places applied before the next is uploaded (the
    places are a history applied in time order)."""
    from fastapi.testclient import TestClient

    from app.db import migrate
    from app.db.session import Database
    from app.main import create_app
    from tests.api.support import auth_headers, create_api_key, make_settings
    from worker.runner import LocalWorker

    settings = make_settings(root, database_url=f"sqlite:///{root / DB_FILE}", run_store=root / RUN_STORE)
    migrate.upgrade(settings.database_url)
    key = create_api_key(settings.database_url, "admin", "demo history")
    n_history = len(data.history.runs)
    history, rest = data.runs[:n_history], data.runs[n_history:]
    db = Database(settings.database_url)
    try:
        with TestClient(create_app(settings), headers=auth_headers(key)) as client:
            # reference data and assets first: a run's places are found when it is published
            for kind, path in data.reference.items():
                r = client.post(f"/api/v1/reference/{kind}", params={"mode": "replace"},
                                files={"file": (path.name, path.read_bytes(), "text/csv")})
                assert r.status_code == 201, r.text
            for path in data.geometry:
                r = client.post("/api/v1/geometry", files={"file": (path.name, path.read_bytes(), "application/geo+json")})
                assert r.status_code in (200, 201), r.text
            r = client.post("/api/v1/assets", files={"file": (data.assets.name, data.assets.read_bytes(), "text/csv")})
            assert r.status_code == 201, r.text
            worker = LocalWorker(settings, db=db, worker_id="history-worker")
            run_ids = []
            try:
                for path in history:
                    with open(path, "rb") as fh:
                        r = client.post("/api/v1/runs", files={"file": (path.name, fh, "application/x-hdf5")})
                    assert r.status_code == 201, r.text
                    assert worker.run(exit_when_idle=True) == 1
                    job = client.get(f"/api/v1/jobs/{r.json()['latest_job']['id']}").json()
                    assert job["status"] == "done", job
                    places = client.get("/api/v1/condition/places", params={"line_id": data.reference_line[0]}).json()
                    assert places["places_pending"] == 0, places
                    run_ids.append(r.json()["id"])
            finally:
                worker.runtime.close()
    finally:
        db.dispose()
    return ProcessedHistory(root, data, tuple(run_ids), tuple(rest))


def processed_history(datasets, length_km: float, fs: float = 10_000.0) -> ProcessedHistory:
    """The demo's history of ``length_km`` km runs at ``fs`` Hz, written and processed once
    (:func:`build_processed_history`; two cached data sets of ``datasets``, tests/datasets.py); the
    user works on a copy (:meth:`ProcessedHistory.copy_to`)."""
    spec = {"length_km": length_km, "fs": fs}

    def files(root: Path):
        from app.simulate.demo import write_demo_dataset

        return write_demo_dataset(root, length_km=length_km, fs=fs, history=True)

    data = datasets.get("demo-history-files", spec, files)
    return datasets.get("demo-history-processed", spec, lambda root: build_processed_history(root, data))
