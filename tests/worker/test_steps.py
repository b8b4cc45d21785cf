"""The job steps both worker modes share (plan and record, fail, metadata, files of a
deleted run) and the one choice of the worker mode."""

from __future__ import annotations

import pytest

from app.analysis.settings import ProcessingSettings
from app.db import queue
from app.db.models import JobStatus
from app.db.session import Database
from app.pipeline import results_meta
from app.settings import Settings
from worker import modes
from worker.steps import (
    WorkerRuntime,
    fail_job,
    job_meta,
    load_job,
    record_plan,
    remove_files_if_deleted,
)


@pytest.fixture
def claimed(client, short_sim_run):
    """The short simulation uploaded and its job claimed by worker "w": (client, runtime, record)."""
    path, _ = short_sim_run
    with open(path, "rb") as fh:
        run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
    rt = WorkerRuntime(client.settings, Database(client.settings.database_url))
    assert queue.claim_next_job(rt.db, "w", 30) == run["latest_job"]["id"]
    yield client, rt, load_job(rt.db, run["latest_job"]["id"])
    rt.close()


def test_record_plan_keeps_finished_chunks_and_drops_half_written_files(claimed):
    client, rt, record = claimed
    run_id, job_id = record.run.id, record.job.id
    job_dir = rt.store.job_dir(run_id, job_id)
    job_dir.mkdir(parents=True)
    (job_dir / "chunk-00000.npz").write_bytes(b"done")
    (job_dir / ".chunk-00001.npz.3f2a.tmp").write_bytes(b"half")
    chunks = record_plan(rt, record, record.run_path(rt.store), worker_id="w")
    assert [c.index for c in chunks] == list(range(len(chunks)))
    assert sorted(p.name for p in job_dir.iterdir()) == ["chunk-00000.npz"]
    assert client.get(f"/api/v1/jobs/{job_id}").json()["n_chunks"] == len(chunks)
    assert record_plan(rt, record, record.run_path(rt.store), worker_id="someone else") is None
    assert record.wheels == ["11", "12", "41", "42"] and record.not_running() is None
    assert record.settings == ProcessingSettings()


def test_fail_job_stores_the_error_text(claimed):
    client, rt, record = claimed
    job_id = record.job.id
    assert not fail_job(rt.db, job_id, ValueError("x" * 5000), worker_id="someone else")
    assert fail_job(rt.db, job_id, ValueError("x" * 5000), worker_id="w")
    body = client.get(f"/api/v1/jobs/{job_id}").json()
    assert body["status"] == JobStatus.FAILED and body["error"] == ("ValueError: " + "x" * 5000)[:4000]
    assert load_job(rt.db, job_id).not_running() == "job failed"


def test_a_failed_jobs_error_reads_in_the_users_language(claimed):
    """A job failed on a run file's error keeps it as a message: the API answers it in the reader's
    language (the job, the run's jobs), the exception's type and the field as they are."""
    from app.core.i18n import _
    from app.io import RunFileError

    client, rt, record = claimed
    job_id, run_id = record.job.id, record.run.id
    assert fail_job(rt.db, job_id, RunFileError("speed", _("run has neither speed nor position")), worker_id="w")
    assert client.get(f"/api/v1/jobs/{job_id}").json()["error"] == "RunFileError: speed: run has neither speed nor position"
    german = client.get(f"/api/v1/jobs/{job_id}", headers={"Accept-Language": "de"}).json()["error"]
    assert german == "RunFileError: speed: die Messfahrt hat weder speed noch position"
    listed = client.get(f"/api/v1/runs/{run_id}/jobs", headers={"Accept-Language": "fr"}).json()["items"]
    assert next(j for j in listed if j["id"] == job_id)["error"] == "RunFileError : speed : le parcours n'a ni speed ni position"


def test_files_of_a_deleted_run_are_removed(claimed):
    client, rt, record = claimed
    run_id = record.run.id
    assert not remove_files_if_deleted(rt, run_id)
    assert rt.store.run_file(run_id).is_file()
    assert client.delete(f"/api/v1/runs/{run_id}").status_code == 204
    late = rt.store.job_dir(run_id, record.job.id) / "chunk-00003.npz"  # written after the deletion
    late.parent.mkdir(parents=True)
    late.write_bytes(b"late")
    assert load_job(rt.db, record.job.id).lost
    assert remove_files_if_deleted(rt, run_id)
    assert not rt.store.run_dir(run_id).exists()


def test_job_meta_of_both_modes():
    settings = ProcessingSettings(chunk_seconds=10)
    local = job_meta(settings, 3, worker_id="host:1:ab", run_sha256="f" * 64, compute_s=1.23456)
    assert local == {**results_meta(settings, 3), "worker": {
        "worker_id": "host:1:ab", "n_chunks": 3, "compute_s": 1.235, "run_sha256": "f" * 64}}
    fanned = job_meta(settings, 3, worker_id="procrastinate:9", run_sha256="f" * 64, mode="procrastinate",
                      assemble_s=0.5004, store_s=0.25)
    assert list(fanned["worker"]) == ["worker_id", "mode", "n_chunks", "assemble_s", "store_s", "run_sha256"]
    assert fanned["worker"]["assemble_s"] == 0.5


def test_the_database_url_picks_the_mode(monkeypatch):
    import worker.hosting
    import worker.runner

    calls = []
    monkeypatch.setattr(worker.runner, "run_worker", lambda s, **kw: calls.append(("local", kw)))
    monkeypatch.setattr(worker.hosting, "run_workers", lambda s, n: calls.append(("workers", n)) or 3)
    monkeypatch.setattr(worker.hosting, "run_worker_process", lambda s, wait: calls.append(("process", wait)) or 0)
    sqlite = Settings(database_url="sqlite:///x.db")
    pg = Settings(database_url="postgresql+psycopg://u:p@db.example/trackvkf")
    assert modes.run(sqlite, once=True) == 0
    assert modes.run(pg, local=True, exit_when_idle=True) == 0
    assert modes.run(pg, processes=4) == 3
    assert modes.run(pg, exit_when_idle=True) == 0
    assert calls == [("local", {"once": True, "exit_when_idle": False}),
                     ("local", {"once": False, "exit_when_idle": True}),
                     ("workers", 4), ("process", False)]

    def interrupted(s, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(worker.runner, "run_worker", interrupted)
    assert modes.run(sqlite) == 130


def test_the_line_curves_wait_for_the_lines_last_active_job(claimed, caplog):
    """While another job of the line is queued or running, a publish leaves the reference curves to that
    job's publish (a history uploaded at once refits them once); the job itself does not count."""
    from app.db.models import ReferenceCurveRow
    from worker.steps import refresh_line_reference

    _, rt, record = claimed
    run = record.run
    assert run.line_id is not None
    assert queue.line_has_active_jobs(rt.db, run.line_id, run.track)
    assert queue.line_has_active_jobs(rt.db, run.line_id, None)
    assert not queue.line_has_active_jobs(rt.db, run.line_id, run.track, besides=record.job.id)
    assert not queue.line_has_active_jobs(rt.db, run.line_id + "-other", run.track)
    assert not queue.line_has_active_jobs(rt.db, run.line_id, (run.track or "") + "-other")
    with caplog.at_level("INFO", logger="worker.steps"):
        refresh_line_reference(rt, run)
    assert "left to the line's next publish" in caplog.text
    with rt.db.read() as session:
        assert session.query(ReferenceCurveRow).count() == 0
