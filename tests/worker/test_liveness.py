"""Worker liveness and queue health (app.operations.liveness) on a real SQLite database:
heartbeats alive / stale / pruned, queue depth, oldest queued age, stuck running jobs, and how
/health reports them."""

from __future__ import annotations

import datetime as dt

import pytest

from app.db.models import Job, JobStatus, utcnow
from app.db.session import Database
from app.operations import liveness
from tests.faults.support import hdf5_run, upload_file


@pytest.fixture
def db(client):
    database = Database(client.settings.database_url)
    yield database
    database.dispose()


def test_heartbeats_alive_stale_forgotten_and_pruned(db):
    now = utcnow()
    liveness.beat(db, "h:1:a", host="h", pid=1, mode="local", now=now - dt.timedelta(seconds=10))
    liveness.beat(db, "h:2:b", host="h", pid=2, mode="procrastinate", now=now - dt.timedelta(days=2))
    liveness.beat(db, "h:3:c", host="h", pid=3, mode="local", now=now - dt.timedelta(seconds=1))
    liveness.beat(db, "h:1:a", host="h", pid=1, mode="local", now=now)  # refreshed
    with db.read() as s:
        q = liveness.queue_health(s, stale_after_s=5, stuck_after_s=60, now=now)
    assert sorted(w.worker_id for w in q.workers_alive) == ["h:1:a", "h:3:c"] and q.workers_lost == 1
    assert q.problems == [] and not q.jobs_waiting
    assert liveness.prune(db, now=now) == 1
    liveness.forget(db, "h:3:c")
    with db.read() as s:
        q = liveness.queue_health(s, stale_after_s=5, stuck_after_s=60, now=now)
    assert [w.worker_id for w in q.workers_alive] == ["h:1:a"] and q.workers_lost == 0
    with pytest.raises(ValueError):
        liveness.beat(db, "", host="h", pid=1, mode="local")
    with db.read() as s, pytest.raises(ValueError):
        liveness.queue_health(s, stale_after_s=0, stuck_after_s=1)


def test_health_reports_queue_depth_age_and_stuck_jobs(client, db, tmp_path):
    ids = [upload_file(client, hdf5_run(tmp_path, n=20_000)).json()["latest_job"]["id"] for _ in range(2)]
    body = client.get("/api/v1/health").json()
    assert body["queue"]["depth"] == 2 and body["queue"]["oldest_queued_age_s"] >= 0
    assert body["status"] == "degraded" and body["problems"] == ["no worker alive while jobs wait"]

    liveness.beat(db, "w:1:x", host="w", pid=1, mode="local")
    body = client.get("/api/v1/health").json()
    assert body["status"] == "ok" and body["workers"] == {"alive": 1, "lost": 0, "by_mode": {"local": 1}}

    old = utcnow() - dt.timedelta(seconds=client.settings.health_stuck_after_s + 5)
    with db.write() as s:  # a job running without progress for longer than the threshold
        job = s.get(Job, ids[0])
        job.status, job.started_at, job.heartbeat_at, job.worker_id = JobStatus.RUNNING, old, old, "w:1:x"
    body = client.get("/api/v1/health").json()
    assert body["queue"] == {"depth": 1, "oldest_queued_age_s": body["queue"]["oldest_queued_age_s"],
                             "running": 1, "stuck": 1}
    assert body["status"] == "degraded" and body["problems"][0].startswith("1 running job(s) without progress")
