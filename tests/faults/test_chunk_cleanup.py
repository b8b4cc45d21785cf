"""Issue 18 item 9: the run store does not grow with every reprocess.

Old jobs' chunk folders were never removed (3 x 39 MB for a 78 MB run; a
cancelled job's too). A job's files are kept only while it is queued or
running: publishing, failing or cancelling a job removes its folder and those
of the older jobs it supersedes, in both worker modes and in the shared store.
A job put back in the queue by a worker's shutdown keeps its chunks (it resumes).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from app.core.runstore import RunStore
from app.db import queue
from app.db.session import Database
from tests.faults.support import hdf5_run, upload_file
from tests.worker.test_tasks import _App, _context, _drain
from worker import runner, tasks
from worker.runner import LocalWorker
from worker.steps import WorkerRuntime

REPROCESS = {"chunk_seconds": 1.0}


def _seed(store: RunStore, run_id: int, job_id: int) -> Path:
    """A chunk file of ``job_id`` as an earlier attempt (or an older version) left it."""
    path = store.chunk_path(run_id, job_id, 0)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"\0" * 1000)
    return path


def _job(client, job_id: int) -> dict:
    return client.get(f"/api/v1/jobs/{job_id}").json()


@pytest.fixture
def local(client, tmp_path):
    """A run uploaded (its first job queued), a local worker and the run store."""
    run = upload_file(client, hdf5_run(tmp_path, n=40_000)).json()
    db = Database(client.settings.database_url)
    worker = LocalWorker(client.settings, db=db)
    yield client, run, worker, RunStore(client.settings.run_store)
    worker.runtime.close()


def test_published_jobs_leave_no_chunk_folders_reprocess_after_reprocess(local):
    client, run, worker, store = local
    first = run["latest_job"]["id"]
    assert worker.run(exit_when_idle=True) == 1
    assert _job(client, first)["status"] == "done"
    assert store.job_ids_with_files(run["id"]) == []
    stale = _seed(store, run["id"], first)  # left by a version that kept them: superseded
    for _ in range(3):
        job = client.post(f"/api/v1/runs/{run['id']}/jobs", json=REPROCESS).json()
        assert worker.run(exit_when_idle=True) == 1
        assert _job(client, job["id"])["status"] == "done"
        assert _job(client, job["id"])["n_chunks"] >= 4
        assert store.job_ids_with_files(run["id"]) == []
    assert not stale.exists()
    assert sorted(p.name for p in store.run_dir(run["id"]).rglob("*") if p.is_file()) == ["run.h5"]


def test_a_failed_job_leaves_no_chunk_folder(local, monkeypatch):
    client, run, worker, store = local
    real = runner.process_chunk
    calls = []

    def second_chunk_fails(run_path, settings, chunk, out, should_cancel):
        calls.append(chunk.index)
        if len(calls) == 2:
            raise RuntimeError("simulated failure in a chunk")
        return real(run_path, settings, chunk, out, should_cancel=should_cancel)

    monkeypatch.setattr(runner, "process_chunk", second_chunk_fails)
    job = client.post(f"/api/v1/jobs/{run['latest_job']['id']}/cancel")  # the default job: 1 chunk
    assert job.status_code == 200
    job = client.post(f"/api/v1/runs/{run['id']}/jobs", json=REPROCESS).json()
    assert worker.run(exit_when_idle=True) == 1
    body = _job(client, job["id"])
    assert body["status"] == "failed" and "simulated failure" in body["error"]
    assert len(calls) == 2  # one chunk file was written before the failure ...
    assert store.job_ids_with_files(run["id"]) == []  # ... and removed with the job's folder


def test_a_cancelled_running_job_leaves_no_chunk_folder(local):
    client, run, worker, store = local
    job_id = run["latest_job"]["id"]
    assert queue.claim_next_job(worker.db, worker.worker_id, 30) == job_id
    seeded = _seed(store, run["id"], job_id)
    assert client.post(f"/api/v1/jobs/{job_id}/cancel").json()["cancel_requested"] is True
    assert worker.process(job_id).status == "cancelled"
    assert not seeded.exists() and store.job_ids_with_files(run["id"]) == []


def test_a_cancelled_queued_job_leaves_no_chunk_folder(local):
    """A job put back in the queue by a worker's shutdown keeps its chunks; cancelled, they go."""
    client, run, worker, store = local
    job_id = run["latest_job"]["id"]
    assert queue.claim_next_job(worker.db, worker.worker_id, 30) == job_id
    seeded = _seed(store, run["id"], job_id)
    worker.stop()
    assert worker.process(job_id).status == "requeued"
    assert _job(client, job_id)["status"] == "queued"
    assert seeded.exists()  # resumes from it
    assert client.post(f"/api/v1/jobs/{job_id}/cancel").json()["status"] == "cancelled"
    assert not seeded.exists() and store.job_ids_with_files(run["id"]) == []


@pytest.fixture
def fanout(make_client, tmp_path):
    """The fan-out tasks (stand-in Procrastinate app) with a shared store: client, run, runtime, store."""
    client = make_client(shared_store=(tmp_path / "shared").as_uri())
    run = upload_file(client, hdf5_run(tmp_path, n=40_000)).json()
    rt = WorkerRuntime(client.settings, Database(client.settings.database_url))
    yield client, run, rt, RunStore(client.settings.run_store, client.settings.shared_store)
    rt.close()


def _shared_job_names(store: RunStore, run_id: int) -> list[str]:
    return store.shared.child_names(f"{run_id}/jobs")


def test_fan_out_publish_removes_chunk_and_wheel_files_in_the_shared_store(fanout):
    client, run, rt, store = fanout
    app = _App()
    for _ in range(3):
        assert tasks.dispatch_jobs(_context(app, rt), timestamp=0) == 1
        ran = _drain(app, rt)
        assert ran[-1] == (tasks.TASK_PUBLISH, "published")
        assert _shared_job_names(store, run["id"]) == []
        assert store.job_ids_with_files(run["id"]) == []
        client.post(f"/api/v1/runs/{run['id']}/jobs", json=REPROCESS)
    # an older job's objects (a version that kept them) go with the next publish
    store.shared.put(store.run_file(run["id"]), f"{run['id']}/jobs/{run['latest_job']['id']}/chunk-00000.npz")
    assert tasks.dispatch_jobs(_context(app, rt), timestamp=0) == 1
    _drain(app, rt)
    assert _shared_job_names(store, run["id"]) == []


def test_fan_out_cancel_removes_the_chunks_already_computed(fanout):
    client, run, rt, store = fanout
    job_id = run["latest_job"]["id"]
    client.post(f"/api/v1/jobs/{job_id}/cancel")
    job_id = client.post(f"/api/v1/runs/{run['id']}/jobs", json=REPROCESS).json()["id"]
    app = _App()
    assert tasks.plan_job(_context(app, rt, job_id=7), job_id=job_id).endswith("deferred")
    assert tasks.run_chunk(_context(app, rt), job_id=job_id, index=0).startswith("chunk 0 done")
    assert _shared_job_names(store, run["id"]) == [str(job_id)]
    assert client.post(f"/api/v1/jobs/{job_id}/cancel").json()["cancel_requested"] is True
    assert tasks.run_chunk(_context(app, rt), job_id=job_id, index=1) == "job running"
    assert _job(client, job_id)["status"] == "cancelled"
    assert _shared_job_names(store, run["id"]) == []
