"""Issue 24 defect 6: with the only worker killed, /health said ok and a job stayed queued or
"running" with nothing telling an operator. Over the real service in both modes (SQLite +
local worker, PostgreSQL + Procrastinate worker): a worker process reports a heartbeat; killed
with SIGKILL while a job waits, /health turns degraded within the stale timeout and names the
problem; a new worker brings it back to ok."""

from __future__ import annotations

import time

import httpx
import pytest

from tests.e2e.support import wait_for
from tests.faults.support import hdf5_run

pytestmark = pytest.mark.timeout(600)


def _health(client: httpx.Client) -> dict:
    r = client.get("/api/v1/health")
    assert r.status_code == 200, r.text
    return r.json()


def test_killing_the_only_worker_turns_health_degraded_while_jobs_wait(service, tmp_path):
    mode = "local" if service.backend == "sqlite" else "procrastinate"
    # a small valid run (4 s of samples): the job only has to wait, and be done by the new worker
    path = hdf5_run(tmp_path, n=40_000)
    with service.client(timeout=120) as client:
        body = _health(client)
        assert body["status"] == "ok" and body["workers"]["alive"] == 0 and body["queue"]["depth"] == 0

        worker = service.start_worker()
        wait_for(lambda: _health(client)["workers"]["by_mode"] == {mode: 1}, 60, "a worker heartbeat", service)
        assert _health(client)["status"] == "ok"

        worker.kill()  # SIGKILL: no clean-up, its heartbeat row stays and goes stale
        worker.wait()
        killed_at = time.monotonic()
        with open(path, "rb") as fh:
            run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
        job_id = run["latest_job"]["id"]
        wait_for(lambda: _health(client)["status"] == "degraded", 30, "health degraded", service)
        seen_after_s = time.monotonic() - killed_at
        body = _health(client)
        assert body["workers"] == {"alive": 0, "lost": 1, "by_mode": {}}
        assert body["queue"]["depth"] == 1 and body["queue"]["oldest_queued_age_s"] >= 0
        assert body["problems"] == ["no worker alive while jobs wait"]
        assert seen_after_s < 3 + 10  # TRACKVKF_WORKER_STALE_AFTER_S=3 in the e2e service

        service.start_worker()
        assert service.wait_job(client, job_id)["status"] == "done"
        wait_for(lambda: _health(client)["status"] == "ok", 30, "health ok again", service)
        body = _health(client)
        assert body["workers"]["alive"] == 1 and body["queue"] == {
            "depth": 0, "oldest_queued_age_s": None, "running": 0, "stuck": 0}
