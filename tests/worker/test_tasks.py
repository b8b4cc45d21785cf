"""The Procrastinate tasks one by one, without a Procrastinate worker: each task is a
module-level function called with a job context (the worker's runtime in
``additional_context``, deferrals recorded by a stand-in app). Driven through the
whole fan-out on SQLite, they store the profile the local job loop stores."""

from __future__ import annotations

import io
from collections import deque
from types import SimpleNamespace
from typing import Any

import pandas as pd
import procrastinate
import pytest
from procrastinate import exceptions as pexc

from app.db.session import Database
from app.settings import Settings
from worker import hosting, tasks
from worker.runner import LocalWorker
from worker.steps import WorkerRuntime

pytestmark = pytest.mark.timeout(300)

SETTINGS = {"chunk_seconds": 4.0}
BY_NAME = {
    tasks.TASK_PLAN: tasks.plan_job,
    tasks.TASK_CHUNK: tasks.run_chunk,
    tasks.TASK_ASSEMBLE: tasks.assemble_job,
    tasks.TASK_STORE_WHEEL: tasks.store_wheel,
    tasks.TASK_PUBLISH: tasks.publish_job,
}


class _App:
    """Stands in for ``procrastinate.App``: records deferrals, honours queueing locks."""

    def __init__(self) -> None:
        self.waiting: deque[tuple[str, str | None, int, dict[str, Any]]] = deque()

    def configure_task(self, name: str, *, queueing_lock: str | None = None, priority: int = 0) -> Any:
        def defer(**kwargs: Any) -> int:
            if queueing_lock is not None and any(lock == queueing_lock for _, lock, _, _ in self.waiting):
                raise pexc.AlreadyEnqueued(queueing_lock)
            self.waiting.append((name, queueing_lock, priority, kwargs))
            return len(self.waiting)

        return SimpleNamespace(defer=defer)


def _context(app: _App, rt: WorkerRuntime, job_id: int = 1) -> procrastinate.JobContext:
    return procrastinate.JobContext(
        app=app, job=SimpleNamespace(id=job_id), start_timestamp=0.0, abort_reason=lambda: None,
        additional_context={tasks.RUNTIME_KEY: rt},
    )


def _drain(app: _App, rt: WorkerRuntime) -> list[tuple[str, str]]:
    """Run the deferred tasks (highest priority first) until none is waiting."""
    done = []
    n = 0
    while app.waiting:
        best = max(app.waiting, key=lambda item: item[2])
        app.waiting.remove(best)
        name, _, _, kwargs = best
        n += 1
        done.append((name, BY_NAME[name](_context(app, rt, job_id=1000 + n), **kwargs)))
    return done


def _profile(client, run_id: int) -> pd.DataFrame:
    r = client.get(f"/api/v1/runs/{run_id}/profile.parquet")
    assert r.status_code == 200, r.text
    return pd.read_parquet(io.BytesIO(r.content)).sort_values(["wheel", "bin"], ignore_index=True)


@pytest.fixture
def uploaded(client, short_sim_run):
    """The short simulation uploaded, its default job cancelled: (client, run_id)."""
    path, _ = short_sim_run
    with open(path, "rb") as fh:
        run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
    client.post(f"/api/v1/jobs/{run['latest_job']['id']}/cancel")
    return client, run["id"]


def test_fan_out_stores_what_the_local_loop_stores(uploaded):
    client, run_id = uploaded
    local_job = client.post(f"/api/v1/runs/{run_id}/jobs", json=SETTINGS).json()["id"]
    db = Database(client.settings.database_url)
    rt = WorkerRuntime(client.settings, db)
    try:
        assert LocalWorker(client.settings, db=db).run(exit_when_idle=True) == 1
        local = _profile(client, run_id)
        job_id = client.post(f"/api/v1/runs/{run_id}/jobs", json=SETTINGS).json()["id"]
        app = _App()
        assert tasks.dispatch_jobs(_context(app, rt), timestamp=0) == 1
        assert tasks.dispatch_jobs(_context(app, rt), timestamp=0) == 0  # queueing lock: one plan task
        ran = _drain(app, rt)
    finally:
        rt.close()
    names = [name for name, _ in ran]
    n_chunks = names.count(tasks.TASK_CHUNK)
    assert names[0] == tasks.TASK_PLAN and n_chunks > 2
    assert names.count(tasks.TASK_STORE_WHEEL) == 4 and names[-1] == tasks.TASK_PUBLISH
    assert ran[-1][1] == "published"
    body = client.get(f"/api/v1/jobs/{job_id}").json()
    assert body["status"] == "done" and body["n_chunks"] == n_chunks
    assert body["meta"]["worker"]["mode"] == "procrastinate"
    assert body["meta"]["worker"]["worker_id"].startswith("procrastinate:")
    assert client.get(f"/api/v1/jobs/{local_job}").json()["meta"]["worker"].keys() == {
        "worker_id", "n_chunks", "compute_s", "run_sha256"}
    pd.testing.assert_frame_equal(_profile(client, run_id), local)


def test_each_task_alone(uploaded):
    client, run_id = uploaded
    job_id = client.post(f"/api/v1/runs/{run_id}/jobs", json=SETTINGS).json()["id"]
    db = Database(client.settings.database_url)
    rt = WorkerRuntime(client.settings, db)
    app = _App()
    try:
        # not planned yet: nothing to do
        assert tasks.run_chunk(_context(app, rt), job_id=job_id, index=0) == "job queued"
        assert tasks.assemble_job(_context(app, rt), job_id=job_id) == "job queued"
        assert tasks.plan_job(_context(app, rt, job_id=7), job_id=job_id).endswith("deferred")
        assert tasks.plan_job(_context(app, rt, job_id=8), job_id=job_id) == "skipped"  # another planner
        chunk_tasks = [kw for name, _, _, kw in app.waiting if name == tasks.TASK_CHUNK]
        assert [kw["index"] for kw in chunk_tasks] == list(range(len(chunk_tasks)))
        assert tasks.assemble_job(_context(app, rt), job_id=job_id) == "chunks missing"
        assert tasks.run_chunk(_context(app, rt), job_id=job_id, index=99) == "unknown chunk"
        first = tasks.run_chunk(_context(app, rt), job_id=job_id, index=0)
        assert first.startswith("chunk 0 done")
        again = tasks.run_chunk(_context(app, rt), job_id=job_id, index=0)  # a duplicate delivery
        assert again.startswith("chunk 0 done")
        assert tasks.store_wheel(_context(app, rt), job_id=job_id, wheel="99") == f"run {run_id} has no wheel '99'"
        assert tasks.publish_job(_context(app, rt), job_id=job_id) == "wheel 11 not stored yet"
        # a cancel request stops the job's tasks
        assert client.post(f"/api/v1/jobs/{job_id}/cancel").status_code in (200, 202)
        assert tasks.run_chunk(_context(app, rt), job_id=job_id, index=1) == "job running"
        assert tasks.dispatch_jobs(_context(app, rt), timestamp=0) == 0
        assert client.get(f"/api/v1/jobs/{job_id}").json()["status"] == "cancelled"
        assert tasks.store_wheel(_context(app, rt), job_id=job_id, wheel="11") == "job cancelled"
    finally:
        rt.close()


def test_a_task_needs_the_worker_runtime():
    context = procrastinate.JobContext(app=_App(), job=SimpleNamespace(id=1), start_timestamp=0.0,
                                       abort_reason=lambda: None)
    with pytest.raises(RuntimeError, match="additional_context"):
        tasks.assemble_job(context, job_id=1)


def test_blueprint_keeps_the_task_names():
    assert {t.name for t in tasks.blueprint.tasks.values()} == {
        tasks.TASK_PLAN, tasks.TASK_CHUNK, tasks.TASK_ASSEMBLE, tasks.TASK_STORE_WHEEL,
        tasks.TASK_PUBLISH, tasks.TASK_DISPATCH, tasks.TASK_RETRY_STALLED,
    }
    settings = Settings(database_url="postgresql+psycopg://u:p@db.example/trackvkf", worker_stale_after_s=12)
    for _ in range(2):  # a worker makes a new app at every restart
        app = hosting.make_app(settings)
        assert set(BY_NAME) | {tasks.TASK_DISPATCH, tasks.TASK_RETRY_STALLED} <= set(app.tasks)
        crons = {name: p.cron for (name, _), p in app.periodic_registry.periodic_tasks.items()}
        assert crons == {tasks.TASK_DISPATCH: "* * * * * */5", tasks.TASK_RETRY_STALLED: "* * * * * */4"}
        assert tasks.plan_job.blueprint is app
