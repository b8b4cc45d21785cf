"""Fault tolerance of the workers over the real service (SQLite + local worker and
PostgreSQL + Procrastinate workers): a worker killed with SIGKILL in the middle of
a job is replaced; the run completes once, with the same result as a clean run;
cancelling a running job stops it."""

from __future__ import annotations

import io
import time

import httpx
import pandas as pd
import pytest
from sqlalchemy import func, select

from app.db.models import JobChunk, ProfileBin
from app.db.session import Database

pytestmark = pytest.mark.timeout(600)

SETTINGS = {"chunk_seconds": 5.0}  # several chunks (7) on the short simulated run


def _profile(client: httpx.Client, run_id: int) -> pd.DataFrame:
    r = client.get(f"/api/v1/runs/{run_id}/profile.parquet")
    assert r.status_code == 200, r.text
    return pd.read_parquet(io.BytesIO(r.content)).sort_values(["wheel", "bin"], ignore_index=True)


def _wait(predicate, timeout_s: float, what: str, service) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}:\n{service.log_text()}")


def test_sigkill_mid_job_then_restart_completes_once_with_same_result(service, short_sim_run):
    path, _ = short_sim_run
    with service.client(timeout=120) as client:
        with open(path, "rb") as fh:
            run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
        run_id, first_job = run["id"], run["latest_job"]["id"]
        # replace the default job by one with several chunks (no worker runs yet)
        assert client.post(f"/api/v1/jobs/{first_job}/cancel").json()["status"] == "cancelled"
        job = client.post(f"/api/v1/runs/{run_id}/jobs", json=SETTINGS).json()
        job_id = job["id"]

        victim = service.start_worker()

        def some_chunks_done() -> bool:
            j = client.get(f"/api/v1/jobs/{job_id}").json()
            return j["n_chunks"] is not None and j["chunks_done"] >= 2

        _wait(some_chunks_done, 180, "two chunks done", service)
        victim.kill()  # SIGKILL: no clean-up, job left 'running' with a stale heartbeat
        victim.wait()
        killed = client.get(f"/api/v1/jobs/{job_id}").json()
        assert killed["status"] == "running"
        assert killed["chunks_done"] < killed["n_chunks"], "job finished before the kill"
        done_before = killed["chunks_done"]

        service.start_worker()
        recovered = service.wait_job(client, job_id)
        assert recovered["status"] == "done", recovered["error"]
        # local worker: the job is claimed again; Procrastinate: the job stays
        # claimed, the killed chunk task is retried (stalled-jobs task)
        assert recovered["attempts"] == (2 if service.backend == "sqlite" else 1)
        assert recovered["chunks_done"] == recovered["n_chunks"] > done_before
        after_crash = _profile(client, run_id)

        # a clean run with the same settings gives the same rows
        clean_job = client.post(f"/api/v1/runs/{run_id}/jobs", json=SETTINGS).json()
        clean = service.wait_job(client, clean_job["id"])
        assert clean["status"] == "done" and clean["attempts"] == 1
        assert clean["settings"] == recovered["settings"]
        reference = _profile(client, run_id)
        pd.testing.assert_frame_equal(after_crash, reference, check_exact=False, rtol=1e-9)

        jobs = client.get(f"/api/v1/runs/{run_id}/jobs").json()["items"]
        assert sorted(j["status"] for j in jobs) == ["cancelled", "done", "done"]

    db = Database(service.database_url)
    try:
        with db.read() as s:
            # one row per (wheel, bin), all from the latest job; one chunk row per chunk
            n_rows = s.scalar(select(func.count()).select_from(ProfileBin))
            assert n_rows == len(reference)
            assert set(s.scalars(select(ProfileBin.job_id).distinct())) == {clean_job["id"]}
            n_chunk_rows = s.scalar(
                select(func.count()).select_from(JobChunk).where(JobChunk.job_id == job_id)
            )
            assert n_chunk_rows == recovered["n_chunks"]
    finally:
        db.dispose()


def test_cancel_running_job(service, short_sim_run):
    path, _ = short_sim_run
    with service.client(timeout=120) as client:
        with open(path, "rb") as fh:
            run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
        client.post(f"/api/v1/jobs/{run['latest_job']['id']}/cancel")
        job_id = client.post(f"/api/v1/runs/{run['id']}/jobs", json=SETTINGS).json()["id"]
        service.start_worker()
        _wait(
            lambda: client.get(f"/api/v1/jobs/{job_id}").json()["chunks_done"] >= 1,
            120, "a chunk done", service,
        )
        r = client.post(f"/api/v1/jobs/{job_id}/cancel")
        assert r.status_code == 200 and r.json()["cancel_requested"] is True
        final = service.wait_job(client, job_id, timeout_s=60)
        assert final["status"] == "cancelled"
        assert final["chunks_done"] < final["n_chunks"]
        r = client.get(f"/api/v1/runs/{run['id']}/profile", params={"wheel": "11"})
        assert r.status_code == 409
