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
from app.simulate.run import simulate_run
from app.simulate.speed import SpeedProfile
from app.simulate.surface import RailSurface, TrackImpact
from app.simulate.track import TrackSection, generate_line
from app.simulate.wheels import WheelFlat
from worker import hosting, tasks
from worker.runner import LocalWorker
from worker.steps import WorkerRuntime

pytestmark = pytest.mark.timeout(300)

SETTINGS = {"chunk_seconds": 4.0}
#: track position of the weld of :func:`weld_run`, m
WELD_M = 12_080.0
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


#: length of the run the fan-out is compared on, km: ~18 s at 10 kHz, five chunks of ``chunk_seconds``
#: (a plan, several chunks, an assembly, four wheels and a publish: every task of the fan-out; twice the
#: length made twice the chunks of the same kind, each processed twice, at ~4 s of compute a chunk)
RUN_KM = 0.4


@pytest.fixture(scope="module")
def small_sim_run(datasets) -> tuple:
    """A simulated run of :data:`RUN_KM` (the session's simulation with forces, shorter; cached)."""
    from tests.conftest import _sim_run

    return datasets.get("sim-run", {"length_km": RUN_KM}, _sim_run(RUN_KM))


@pytest.fixture
def uploaded(client, small_sim_run):
    """The short simulation uploaded, its default job cancelled: (client, run_id)."""
    path, _ = small_sim_run
    with open(path, "rb") as fh:
        run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
    client.post(f"/api/v1/jobs/{run['latest_job']['id']}/cancel")
    return client, run["id"]


def _local_then_fan_out(client, run_id: int) -> tuple[dict[str, Any], dict[str, Any]]:
    """The run processed by the local job loop, then by the fan-out tasks; what each stored:
    ``{"job": <job body>, "profile": <profile rows>, "wheels": <wheel results>}``, local first."""
    db = Database(client.settings.database_url)
    rt = WorkerRuntime(client.settings, db)
    stored = []
    try:
        local_job = client.post(f"/api/v1/runs/{run_id}/jobs", json=SETTINGS).json()["id"]
        assert LocalWorker(client.settings, db=db).run(exit_when_idle=True) == 1
        stored.append(_stored(client, run_id, local_job))
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
    fan_out = _stored(client, run_id, job_id)
    assert fan_out["job"]["status"] == "done" and fan_out["job"]["n_chunks"] == n_chunks
    assert fan_out["job"]["meta"]["worker"]["mode"] == "procrastinate"
    assert fan_out["job"]["meta"]["worker"]["worker_id"].startswith("procrastinate:")
    assert stored[0]["job"]["meta"]["worker"].keys() == {"worker_id", "n_chunks", "compute_s", "run_sha256"}
    return stored[0], fan_out


def _stored(client, run_id: int, job_id: int) -> dict[str, Any]:
    wheels = client.get(f"/api/v1/runs/{run_id}/wheels")
    assert wheels.status_code == 200, wheels.text
    return {"job": client.get(f"/api/v1/jobs/{job_id}").json(), "profile": _profile(client, run_id),
            "wheels": wheels.json()}


def _same_results(local: dict[str, Any], fan_out: dict[str, Any]) -> None:
    """The two modes stored the same rows, wheel results and results meta."""
    pd.testing.assert_frame_equal(fan_out["profile"], local["profile"])
    wheels = [[{k: v for k, v in w.items() if k != "job_id"} for w in s["wheels"]["items"]] for s in (local, fan_out)]
    assert wheels[1] == wheels[0]
    meta = [_results_meta(s["job"]["meta"]) for s in (local, fan_out)]
    assert meta[1] == meta[0]


def _results_meta(meta: dict[str, Any]) -> dict[str, Any]:
    """A job's meta less the worker's own and what the places did (the second job of a run keeps the
    places its first found)."""
    out = {k: v for k, v in meta.items() if k != "worker"}
    out["condition"] = {k: v for k, v in meta["condition"].items() if k != "places"}
    return out


def test_fan_out_stores_what_the_local_loop_stores(uploaded):
    client, run_id = uploaded
    local, fan_out = _local_then_fan_out(client, run_id)
    _same_results(local, fan_out)


@pytest.fixture(scope="module")
def weld_run(tmp_path_factory):
    """A 0.5 km simulated run over a 0.3 mm, 1 m dipped weld on both rails at 12 080 m, with a
    40 mm, 0.2 mm flat on wheel 11 (the run of tests/pipeline/test_impacts_pipeline.py)."""
    surface = RailSurface(1, None, (TrackImpact(WELD_M, 1.0, 0.3e-3, 1), TrackImpact(WELD_M, 1.0, 0.3e-3, 2)))
    line = generate_line(11_900.0, 12_700.0, 5, sections=[TrackSection(11_900.0, 12_700.0, "b91_no_pads")],
                         anomalies=[], surface=surface)
    speed = SpeedProfile.from_segments(30.0, [(4.0, 30.0), (6.0, 42.0), (10.0, 42.0)])
    path = tmp_path_factory.mktemp("weld") / "weld-run.h5"
    simulate_run(path, length_km=0.5, fs=10_000.0, seed=2, line=line, speed_profile=speed,
                 wheel_flats={"11": WheelFlat(0.04, 0.2e-3, angle_rad=2.0)}, with_forces=False)
    return path


def test_fan_out_bridges_track_impacts_as_the_local_loop_does(client, weld_run):
    """On a run over a weld: the same bridged rows, ``meta["track_impacts"]`` and wheel flat in both modes."""
    with open(weld_run, "rb") as fh:
        run = client.post("/api/v1/runs", files={"file": (weld_run.name, fh)}).json()
    client.post(f"/api/v1/jobs/{run['latest_job']['id']}/cancel")
    local, fan_out = _local_then_fan_out(client, run["id"])
    impacts = local["job"]["meta"]["track_impacts"]
    assert [round(i["track_m"]) for i in impacts] == [round(WELD_M)]  # the weld, found and masked
    assert local["profile"]["track_impact_mm"].notna().sum() == 4  # at its bin, on every wheel
    assert any(w.get("flat") for w in local["wheels"]["items"])
    _same_results(local, fan_out)


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
