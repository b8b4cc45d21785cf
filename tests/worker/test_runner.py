"""The local worker loop in-process with the real pipeline: graceful stop re-queues
and keeps finished chunks, errors fail the job with their text, a run deleted
mid-job stops the worker without leaving files or rows."""

from __future__ import annotations

import threading
import time

import pandas as pd
import pytest
from sqlalchemy import func, select

from app.db import crud, results_reader
from app.db.models import Job, JobStatus, ProfileBin
from app.db.session import Database
from tests.api.support import store_files
from worker import runner
from worker.runner import LocalWorker

pytestmark = pytest.mark.timeout(300)

SETTINGS = {"chunk_seconds": 5.0}


@pytest.fixture
def queued(client, short_sim_run):
    """A run of the short simulation with one queued multi-chunk job: (client, run_id, job_id)."""
    path, _ = short_sim_run
    with open(path, "rb") as fh:
        run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
    client.post(f"/api/v1/jobs/{run['latest_job']['id']}/cancel")
    job = client.post(f"/api/v1/runs/{run['id']}/jobs", json=SETTINGS).json()
    return client, run["id"], job["id"]


def _job(db: Database, job_id: int) -> Job | None:
    with db.read() as s:
        return crud.get_job(s, job_id)


def _chunks_done(db: Database, job_id: int) -> int:
    with db.read() as s:
        return crud.chunk_counts(s, [job_id]).get(job_id, {}).get("done", 0)


def _run_in_thread(worker: LocalWorker) -> threading.Thread:
    thread = threading.Thread(target=worker.run, kwargs={"once": True}, daemon=True)
    thread.start()
    return thread


def _wait(predicate, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.05)
    raise AssertionError("timed out")


def test_graceful_stop_requeues_and_resume_reuses_chunks(queued, monkeypatch):
    client, run_id, job_id = queued
    settings = client.settings
    db = Database(settings.database_url)
    try:
        worker = LocalWorker(settings, db=db)
        thread = _run_in_thread(worker)
        _wait(lambda: _chunks_done(db, job_id) >= 2)
        worker.stop()
        thread.join(timeout=60)
        assert not thread.is_alive()
        job = _job(db, job_id)
        assert job.status == JobStatus.QUEUED and job.worker_id is None
        job_dir = settings.run_store / str(run_id) / "jobs" / str(job_id)
        kept = {int(p.name[6:11]) for p in job_dir.glob("chunk-*.npz")}
        assert len(kept) >= 2

        computed: list[int] = []
        real = runner.process_chunk

        def recording(run_path, settings, chunk, out, should_cancel):
            computed.append(chunk.index)
            return real(run_path, settings, chunk, out, should_cancel=should_cancel)

        monkeypatch.setattr(runner, "process_chunk", recording)
        assert LocalWorker(settings, db=db).run(exit_when_idle=True) == 1
        job = _job(db, job_id)
        assert job.status == JobStatus.DONE and job.attempts == 2
        assert sorted(computed) == sorted(set(range(job.n_chunks)) - kept)  # kept chunks not recomputed
        assert not job_dir.exists()  # published: the job's chunk files are no longer needed
    finally:
        db.dispose()


def test_error_fails_job_with_its_text(queued):
    client, run_id, job_id = queued
    settings = client.settings
    (settings.run_store / str(run_id) / "run.h5").write_bytes(b"not an hdf5 file")
    db = Database(settings.database_url)
    try:
        assert LocalWorker(settings, db=db).run(exit_when_idle=True) == 1
        job = _job(db, job_id)
        assert job.status == JobStatus.FAILED
        assert job.error and len(job.error) > 10
        assert job.finished_at is not None
    finally:
        db.dispose()
    body = client.get(f"/api/v1/jobs/{job_id}").json()
    assert body["status"] == "failed" and body["error"] == job.error


def test_run_deleted_mid_job_leaves_nothing(queued):
    client, run_id, job_id = queued
    settings = client.settings
    db = Database(settings.database_url)
    try:
        worker = LocalWorker(settings, db=db)
        thread = _run_in_thread(worker)
        _wait(lambda: _chunks_done(db, job_id) >= 1)
        assert client.delete(f"/api/v1/runs/{run_id}").status_code == 204
        thread.join(timeout=60)
        assert not thread.is_alive()
        assert _job(db, job_id) is None
        with db.read() as s:
            assert s.scalar(select(func.count()).select_from(ProfileBin)) == 0
    finally:
        db.dispose()
    assert store_files(settings.run_store) == []


def test_parallel_chunks_give_the_sequential_result(queued):
    client, run_id, job_id = queued
    db = Database(client.settings.database_url)
    try:
        parallel = client.settings.model_copy(update={"worker_chunk_processes": 2})
        assert LocalWorker(parallel, db=db).run(exit_when_idle=True) == 1
        job = _job(db, job_id)
        assert job.status == JobStatus.DONE, job.error
        assert _chunks_done(db, job_id) == job.n_chunks > 2
        with db.read() as s:
            first = results_reader.profile_rows(s, run_id)
        again = client.post(f"/api/v1/runs/{run_id}/jobs", json=SETTINGS).json()["id"]
        assert LocalWorker(client.settings, db=db).run(exit_when_idle=True) == 1
        assert _job(db, again).status == JobStatus.DONE
        with db.read() as s:
            second = results_reader.profile_rows(s, run_id)
    finally:
        db.dispose()
    assert len(first) > 1000
    pd.testing.assert_frame_equal(first, second)
