"""Real faults on both modes (SQLite + local worker, PostgreSQL + Procrastinate):
two workers competing for one run (both modes), the database restarted while chunks
run and the same chunk delivered twice (PostgreSQL: a database server, Procrastinate's
task delivery), the API killed during an upload (SQLite: the API dies while it
receives the body, before it writes to any database; the run uploaded again is
processed as in the competing workers' test). Each ends with the run's profile
identical to a clean run's and every row stored once."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import httpx
import pytest
from sqlalchemy import text

from app.db.session import Database
from app.settings import Settings
from tests.api.support import store_files
from tests.e2e.conftest import Service, running_service
from tests.e2e.support import (
    assert_rows_once,
    assert_same_as_clean,
    job,
    profile,
    upload_with_job,
    wait_final,
    wait_for,
)

pytestmark = pytest.mark.timeout(600)


def _places_done(client, job_id) -> bool:
    """The job's places follow-up (after its publish commit, issue 24) has run."""
    return not (((job(client, job_id).get("meta") or {}).get("condition") or {}).get("places") or {}).get("pending")


def _finish_and_check(client, service, run_id, job_id, clean_reference) -> dict:
    final = wait_final(client, job_id, service)
    assert final["status"] == "done", f"{final['error']}\n{service.log_text()}"
    wait_for(lambda: _places_done(client, job_id), 120, "places follow-up", service)
    final = job(client, job_id)
    assert final["progress"] == 1.0 and final["chunks_done"] == final["n_chunks"] >= 5
    got = profile(client, run_id)
    assert_same_as_clean(got, clean_reference)
    assert_rows_once(service.database_url, job_id, len(got), final["n_chunks"])
    return final


def test_two_workers_compete_for_the_same_run(service, short_sim_run, clean_reference):
    path, _ = short_sim_run
    with service.client(timeout=120) as client:
        run_id, job_id = upload_with_job(client, path)
        workers = [service.start_worker(), service.start_worker()]
        _finish_and_check(client, service, run_id, job_id, clean_reference)
    service.stop()
    logs = [log.read_text(errors="replace") for log in service.logs if log.name.startswith("worker")]
    assert len(logs) == len(workers) == 2
    if service.backend == "postgresql":
        # the chunks of the one run were shared between both workers
        for text_ in logs:
            assert f"job {job_id} chunk" in text_, service.log_text()


#: the embedded SQLite database is a file: no server to restart
@pytest.mark.parametrize("service", ["postgresql"], indirect=True)
def test_database_restart_while_chunks_run(service, short_sim_run, clean_reference):
    path, _ = short_sim_run
    with service.client(timeout=120) as client:
        run_id, job_id = upload_with_job(client, path)
        service.start_worker()
        service.start_worker()
        wait_for(lambda: job(client, job_id)["chunks_done"] >= 1, 180, "a chunk done", service)
        before = job(client, job_id)
        assert before["status"] == "running" and before["chunks_done"] < before["n_chunks"]
        service.pg.restart(down_s=2.0)  # clients lose their connections mid-chunk
        _finish_and_check(client, service, run_id, job_id, clean_reference)


def _procrastinate_pending(database_url: str) -> int:
    db = Database(database_url)
    try:
        with db.read() as s:
            return int(s.scalar(text(
                "SELECT count(*) FROM procrastinate_jobs WHERE status IN ('todo', 'doing') AND task_name IN "
                "('trackvkf.process_chunk', 'trackvkf.assemble_job', 'trackvkf.store_wheel', 'trackvkf.publish_job')"
            )))
    finally:
        db.dispose()


@pytest.fixture
def object_store_service(pg_cluster, tmp_path, migrated_databases) -> Iterator[Service]:
    """The service on PostgreSQL with a shared fsspec store (``tmp_path / "shared-store"``, file:// here,
    s3:// in production) from its start."""
    if isinstance(pg_cluster, str):
        pytest.skip(pg_cluster)
    with running_service(tmp_path, migrated_databases.postgresql(pg_cluster), backend="postgresql", pg=pg_cluster,
                         env_overrides={"TRACKVKF_SHARED_STORE": f"file://{tmp_path / 'shared-store'}"}) as svc:
        yield svc


#: task delivery is Procrastinate's (the local worker owns whole jobs)
def test_same_chunk_delivered_twice_on_hosts_sharing_only_an_object_store(
    object_store_service, short_sim_run, clean_reference
):
    from worker.hosting import make_app
    from worker.tasks import TASK_ASSEMBLE, TASK_CHUNK, TASK_PUBLISH, TASK_STORE_WHEEL

    service = object_store_service
    path, _ = short_sim_run
    # two "hosts" without a common file system: the API's run store, the workers' own
    # run store, and a shared fsspec store (file:// here, s3:// in production)
    shared = service.workdir / "shared-store"
    worker_store = service.workdir / "worker-host-runs"
    assert service.env["TRACKVKF_SHARED_STORE"] == f"file://{shared}"
    app = make_app(Settings(database_url=service.database_url, run_store=worker_store,
                            shared_store=f"file://{shared}"))
    with service.client(timeout=120) as client, app.open():
        run_id, job_id = upload_with_job(client, path)
        assert (shared / str(run_id) / "run.h5").read_bytes() == (service.run_store / str(run_id) / "run.h5").read_bytes()
        service.env["TRACKVKF_RUN_STORE"] = str(worker_store)
        service.start_worker()
        wait_for(lambda: job(client, job_id)["n_chunks"] is not None, 120, "chunks planned", service)
        n_chunks = job(client, job_id)["n_chunks"]
        # every chunk, the assembly and every wheel delivered a second time, without queueing locks
        for index in range(n_chunks):
            app.configure_task(TASK_CHUNK).defer(job_id=job_id, index=index)
        app.configure_task(TASK_ASSEMBLE).defer(job_id=job_id)
        for wheel in ("11", "12", "41", "42"):
            app.configure_task(TASK_STORE_WHEEL).defer(job_id=job_id, wheel=wheel)
        service.start_worker()
        first = _finish_and_check(client, service, run_id, job_id, clean_reference)
        # ... and once more after the job is done: nothing changes
        app.configure_task(TASK_CHUNK).defer(job_id=job_id, index=0)
        app.configure_task(TASK_ASSEMBLE).defer(job_id=job_id)
        app.configure_task(TASK_STORE_WHEEL).defer(job_id=job_id, wheel="41")
        app.configure_task(TASK_PUBLISH).defer(job_id=job_id)
        wait_for(lambda: _procrastinate_pending(service.database_url) == 0, 120,
                 "duplicate deliveries processed", service)
        again = _finish_and_check(client, service, run_id, job_id, clean_reference)
        assert again["finished_at"] == first["finished_at"]
        assert again["meta"] == first["meta"]
        # the worker host fetched the run file once from the shared store; the job's chunk and
        # wheel results lived there while it ran and went with its publication (late duplicate
        # deliveries of a done job write nothing back)
        assert (worker_store / str(run_id) / "run.h5").is_file()
        results = sorted(p.name for p in (shared / str(run_id)).rglob("*") if p.is_file())
        assert results == ["run.h5"]
        assert not list(worker_store.rglob("*.npz")) and not list(service.run_store.rglob("*.npz"))
        # deleting the run removes its objects from the shared store too
        assert client.delete(f"/api/v1/runs/{run_id}").status_code == 204
        assert not (shared / str(run_id)).exists()


#: the API receives the body into the run store before it writes to the database: the kill and the sweep
#: are the same in both modes, and the processing of the run uploaded again on PostgreSQL is
#: test_two_workers_compete_for_the_same_run's
@pytest.mark.parametrize("service", ["sqlite"], indirect=True)
def test_api_killed_during_upload_leaves_nothing(service, short_sim_run, clean_reference):
    path, _ = short_sim_run
    data = path.read_bytes()
    sent = threading.Event()
    release = threading.Event()

    def slow_body():
        block = 256 * 1024
        for i in range(0, len(data), block):
            yield data[i : i + block]
            if i >= len(data) // 3:
                sent.set()
                release.wait(30)  # hold the upload open until the API is gone

    errors: list[BaseException] = []

    def upload() -> None:
        try:
            with service.client(timeout=60) as c:
                c.post("/api/v1/runs", params={"filename": path.name, "format": "hdf5"},
                       content=slow_body(), headers={"content-type": "application/octet-stream"})
        except httpx.HTTPError as exc:
            errors.append(exc)

    uploader = threading.Thread(target=upload)
    uploader.start()
    assert sent.wait(60), service.log_text()
    wait_for(lambda: any(p.stat().st_size > 0 for p in store_files(service.run_store / ".uploads")),
             30, "upload data in the run store", service)
    service.kill_api()  # SIGKILL mid-upload
    release.set()
    uploader.join(60)
    assert errors, "the upload should have failed with the API gone"
    assert store_files(service.run_store / ".uploads"), "expected a partial upload on disk"

    # restarted API: uploads older than the stale age belong to the dead API and go
    time.sleep(1.5)
    service.env["TRACKVKF_UPLOAD_STALE_AFTER_S"] = "1"
    service.start_api()
    assert store_files(service.run_store) == []
    with service.client(timeout=120) as client:
        assert client.get("/api/v1/runs").json()["total"] == 0
        assert client.get("/api/v1/jobs").json()["total"] == 0
        # the same file uploaded again in full is processed like a clean run
        run_id, job_id = upload_with_job(client, path)
        service.start_worker()
        _finish_and_check(client, service, run_id, job_id, clean_reference)
