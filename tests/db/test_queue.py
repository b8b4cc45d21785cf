"""The SQL job queue: atomic claims, stale-heartbeat re-claims, guarded writes,
progress from chunk rows. (Publishing results: tests/publish/.)"""

from __future__ import annotations

import datetime as dt
import threading

import pytest
from sqlalchemy import update

from app import publish
from app.db import crud, queue
from app.db.models import Job, JobStatus, utcnow
from tests.db.support import job_results as _results
from tests.db.support import make_run_with_job as _make_run


def test_claim_is_exclusive_under_races(db):
    _, job_id = _make_run(db)
    winners: list[int | None] = []
    barrier = threading.Barrier(6)

    def claim(i: int) -> None:
        barrier.wait()
        winners.append(queue.claim_next_job(db, f"w{i}", stale_after_s=30))

    threads = [threading.Thread(target=claim, args=(i,)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(w for w in winners if w is not None) == [job_id]
    with db.read() as s:
        job = s.get(Job, job_id)
        assert job.status == JobStatus.RUNNING and job.attempts == 1 and job.started_at


def test_oldest_job_first_and_nothing_when_empty(db):
    _, first = _make_run(db, "a" * 64)
    _, second = _make_run(db, "b" * 64)
    assert queue.claim_next_job(db, "w", 30) == first
    assert queue.claim_next_job(db, "w", 30) == second
    assert queue.claim_next_job(db, "w", 30) is None


def test_stale_job_is_reclaimed_and_old_worker_loses_it(db):
    run_id, job_id = _make_run(db)
    assert queue.claim_next_job(db, "dead", 30) == job_id
    assert queue.claim_next_job(db, "other", 30) is None  # heartbeat fresh
    with db.write() as s:
        s.execute(update(Job).values(heartbeat_at=utcnow() - dt.timedelta(seconds=60)))
    assert queue.claim_next_job(db, "other", 30) == job_id
    assert queue.heartbeat(db, job_id, "dead").owned is False
    assert queue.mark_chunk(db, job_id, 0, "done", worker_id="dead") is None
    profiles, wheels = _results(4, 1.0)
    assert not publish.publish_job(db, job_id, run_id, profiles, wheels, {}, worker_id="dead")
    assert publish.publish_job(db, job_id, run_id, profiles, wheels, {"v": 1}, worker_id="other")
    with db.read() as s:
        job = s.get(Job, job_id)
        assert job.status == JobStatus.DONE and job.attempts == 2 and job.progress == 1.0


def test_progress_counts_chunk_rows_not_events(db):
    _, job_id = _make_run(db)
    queue.claim_next_job(db, "w", 30)
    specs = [(i, {"index": i}) for i in range(4)]
    assert queue.record_chunks(db, job_id, specs, worker_id="w")
    assert queue.record_chunks(db, job_id, specs, worker_id="w")  # idempotent
    assert queue.mark_chunk(db, job_id, 0, "done", worker_id="w") == pytest.approx(0.25)
    assert queue.mark_chunk(db, job_id, 0, "done", worker_id="w") == pytest.approx(0.25)
    assert queue.mark_chunk(db, job_id, 1, "done", worker_id="w") == pytest.approx(0.5)
    with db.read() as s:
        assert crud.chunk_counts(s, [job_id]) == {job_id: {"done": 2, "pending": 2}}
        assert s.get(Job, job_id).n_chunks == 4


def test_release_and_cancel(db):
    _, job_id = _make_run(db)
    queue.claim_next_job(db, "w", 30)
    assert queue.release_job(db, job_id, "w")
    with db.read() as s:
        assert s.get(Job, job_id).status == JobStatus.QUEUED
    assert queue.claim_next_job(db, "w2", 30) == job_id
    with db.write() as s:
        assert crud.request_cancel(s, job_id) == "requested"
    lease = queue.heartbeat(db, job_id, "w2")
    assert lease.owned and lease.cancel_requested
    assert queue.finish_job(db, job_id, JobStatus.CANCELLED, "cancelled by request", worker_id="w2")
    with db.write() as s:
        assert crud.request_cancel(s, job_id) == "final"
        assert crud.request_cancel(s, 12345) is None
