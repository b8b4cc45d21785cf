"""Production mode: Procrastinate tasks on PostgreSQL, workers on any number of hosts.

A job is fanned out into tasks that run the same pure functions as the local
worker (:func:`app.pipeline.plan_chunks`, :func:`~app.pipeline.process_chunk`,
:func:`~app.pipeline.assemble_wheel`), through the same job steps
(:mod:`worker.steps`) and chunk store (:class:`~worker.chunkstore.ChunkStore`)::

    jobs row 'queued' ──NOTIFY at commit (fallback: dispatch_jobs, every 5 s)──▶ plan_job(job_id)
        plan_job:      claim the job, plan chunks, record chunk rows,
                       defer run_chunk(job_id, index) for every chunk not done
        run_chunk:     chunk result file (atomic: temp + rename) → chunk row 'done';
                       the task that sees all chunks done defers assemble_job
        assemble_job:  defer store_wheel(job_id, wheel) for every wheel
        store_wheel:   merge the wheel's sums from the chunk files → its profile
                       rows (one transaction, keyed by the job: not yet visible),
                       then its OOR result file; the task that sees every wheel
                       stored defers publish_job
        publish_job:   the run's track impacts from the chunk files, bridged in
                       the stored rows (app.pipeline.finish_assembly, as the local
                       worker ends: the same rows and meta), then the publish step
                       (app.publish.publish_job), one transaction: the bridged
                       rows replace the job's (if there was an impact), the
                       run's wheel rows replaced, the older jobs' profile rows
                       deleted, the condition rows and alerts written, the job
                       marked 'done' (readers show a run's latest done job: they
                       switch from the old to the new results at this commit),
                       the run marked places pending; then the places follow-up
                       in transactions of its own (app.places.followup; a task
                       killed before it: the workers' places-followup loop)

The wheels are stored in parallel by as many workers as are free, so the
tail after the last chunk shrinks with the number of workers too.

Delivery is at-least-once (Procrastinate's retries, and the documented
stalled-jobs periodic task :func:`retry_stalled_jobs` for workers that died),
and every step is idempotent:

* a chunk result is a file written atomically; computing it twice writes the
  same file, and a file that exists is not computed again;
* chunk rows are unique per (job, chunk) and only change status; progress is
  done rows / all rows, never a counter;
* a wheel's rows (primary key job, wheel, bin) are replaced in one
  transaction, only while the job is running; its result file is written
  after the commit, and a stored wheel is not stored again;
* publishing is guarded by ``status = 'running'``: a second publish of a done
  job changes nothing; a job that fails or is cancelled drops its unpublished
  rows in the transaction that marks it so;
* deferrals use queueing locks (one waiting copy per chunk / wheel / job), and
  a duplicate that slips through is harmless by the rules above.

Cancel (API ``POST /jobs/{id}/cancel``) sets ``cancel_requested``; running
chunks stop at their next sub-block (``should_cancel`` polls the job row) and
mark the job cancelled, and the dispatcher does so within 5 s for a job with
no chunk running.

The tasks are declared at module level on the Procrastinate blueprint
:data:`blueprint` (each importable and callable alone with a
:class:`procrastinate.JobContext`); :func:`worker.hosting.make_app` binds them to
an app on a database, under their unchanged names (``trackvkf.plan_job``,
``trackvkf.process_chunk`` …), so tasks queued by an earlier version still run. A
worker process (:mod:`worker.hosting`) hands its :class:`~worker.steps.WorkerRuntime`
(settings, database, stores, stop flag) to the tasks through Procrastinate's
``additional_context`` (:func:`runtime_of`).
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import procrastinate
import psycopg
import sqlalchemy.exc
from procrastinate import exceptions as pexc

from app import publish
from app.core.jsonable import jsonable
from app.db import queue
from app.db.models import ChunkStatus
from app.db.results_reader import job_profile_frame
from app.pipeline import (
    ChunkSpec,
    PipelineCancelled,
    RunResults,
    finish_assembly,
    process_chunk,
    wheel_assembly,
)
from worker.steps import (
    JobRecord,
    WorkerRuntime,
    discard_job_files,
    end_failed,
    end_published,
    finalize_cancels,
    job_meta,
    load_job,
    mark_chunk_done,
    record_plan,
    remove_files_if_deleted,
)

__all__ = [
    "TASK_PLAN",
    "TASK_CHUNK",
    "TASK_ASSEMBLE",
    "TASK_STORE_WHEEL",
    "TASK_PUBLISH",
    "TASK_DISPATCH",
    "TASK_RETRY_STALLED",
    "RUNTIME_KEY",
    "blueprint",
    "dispatch_jobs",
    "retry_stalled_jobs",
    "plan_job",
    "run_chunk",
    "assemble_job",
    "store_wheel",
    "publish_job",
    "runtime_of",
]

log = logging.getLogger(__name__)

TASK_PLAN = "trackvkf.plan_job"
TASK_CHUNK = "trackvkf.process_chunk"
TASK_ASSEMBLE = "trackvkf.assemble_job"
TASK_STORE_WHEEL = "trackvkf.store_wheel"
TASK_PUBLISH = "trackvkf.publish_job"
TASK_DISPATCH = "trackvkf.dispatch_jobs"
TASK_RETRY_STALLED = "trackvkf.retry_stalled_jobs"
#: key of the worker process's WorkerRuntime in the tasks' ``context.additional_context``
RUNTIME_KEY = "trackvkf_runtime"

#: priorities (higher first): bookkeeping before chunks, so results land early
PRIORITY_HIGH = 10
PRIORITY_CHUNK = 0
#: job file holding a stored wheel's OOR result (its presence: the wheel is stored)
_WHEEL_FILE = "wheel-{wheel}.json"
#: seconds between two runs of the periodic dispatcher (a fallback: jobs are planned on NOTIFY)
_DISPATCH_EVERY_S = 5
#: seconds between two looks of a running chunk at its job row (cancel)
_CANCEL_POLL_S = 0.5
#: value of ``meta["worker"]["mode"]`` of the jobs these tasks run
_MODE = "procrastinate"


class WorkerShutdown(RuntimeError):
    """A chunk was interrupted because its worker is shutting down (retried elsewhere)."""


#: database and connection errors: the task is retried (database restart, network)
TRANSIENT_ERRORS: tuple[type[BaseException], ...] = (
    sqlalchemy.exc.OperationalError,
    sqlalchemy.exc.InterfaceError,
    sqlalchemy.exc.DisconnectionError,
    psycopg.OperationalError,
    psycopg.InterfaceError,
    pexc.ConnectorException,
    WorkerShutdown,
)

_RETRY = procrastinate.RetryStrategy(
    max_attempts=20, wait=1, linear_wait=1, retry_exceptions=set(TRANSIENT_ERRORS)
)

#: the tasks of trackvkf, bound to an app by :func:`make_app`
blueprint = procrastinate.Blueprint()


def runtime_of(context: procrastinate.JobContext) -> WorkerRuntime:
    """The :class:`~worker.steps.WorkerRuntime` of the worker process running a task."""
    try:
        return context.additional_context[RUNTIME_KEY]
    except KeyError:
        raise RuntimeError(
            f"the worker passes no {RUNTIME_KEY!r} in additional_context (see run_worker_process)"
        ) from None


def _is_transient(exc: BaseException) -> bool:
    return isinstance(exc, TRANSIENT_ERRORS)


def _defer(app: procrastinate.App, name: str, lock: str | None, priority: int, **kwargs: Any) -> bool:
    """Defer a task; False if an identical one is already waiting (queueing lock)."""
    try:
        app.configure_task(name, queueing_lock=lock, priority=priority).defer(**kwargs)
        return True
    except pexc.AlreadyEnqueued:
        return False


# --- periodic bookkeeping ---------------------------------------------------------
# new jobs are planned at once on their NOTIFY (_plan_on_notify); this is the
# fallback and finishes cancel requests of jobs without a running chunk
@blueprint.periodic(cron=f"* * * * * */{_DISPATCH_EVERY_S}")
@blueprint.task(name=TASK_DISPATCH, queueing_lock=TASK_DISPATCH, priority=PRIORITY_HIGH, pass_context=True)
def dispatch_jobs(context: procrastinate.JobContext, timestamp: int) -> int:  # noqa: ARG001
    """Fan queued jobs out to :func:`plan_job`; finish cancel requests."""
    rt = runtime_of(context)
    finalize_cancels(rt)
    n = 0
    for job_id in queue.queued_job_ids(rt.db):
        n += _defer(context.app, TASK_PLAN, f"plan:{job_id}", PRIORITY_HIGH, job_id=job_id)
    return n


# scheduled by make_app: its period follows the settings' worker_stale_after_s
@blueprint.task(name=TASK_RETRY_STALLED, queueing_lock=TASK_RETRY_STALLED, priority=PRIORITY_HIGH,
                pass_context=True)
async def retry_stalled_jobs(context: procrastinate.JobContext, timestamp: int) -> int:  # noqa: ARG001
    """Retry the jobs of workers whose heartbeat is older than ``worker_stale_after_s``."""
    stalled = await context.app.job_manager.get_stalled_jobs(
        seconds_since_heartbeat=runtime_of(context).settings.worker_stale_after_s
    )
    n = 0
    for job in stalled:
        log.warning("retrying stalled job %s %s%s", job.id, job.task_name, job.task_kwargs)
        await context.app.job_manager.retry_job(job)
        n += 1
    return n


# --- the fan-out -------------------------------------------------------------------
@blueprint.task(name=TASK_PLAN, retry=_RETRY, pass_context=True)
def plan_job(context: procrastinate.JobContext, job_id: int) -> str:
    """Claim a queued job, record its chunks and defer one task per chunk."""
    rt = runtime_of(context)
    owner = f"{queue.FANOUT_OWNER_PREFIX}{context.job.id}"
    if not queue.claim_for_fanout(rt.db, job_id, owner):
        return "skipped"
    record = None
    try:
        record = load_job(rt.db, job_id)
        if record.lost:
            return "lost"
        run_path = record.run_path(rt.store)  # fetched from the shared store if need be
        chunks = record_plan(rt, record, run_path, worker_id=owner)
        if chunks is None:
            return "lost"
    except Exception as exc:
        if _is_transient(exc):
            raise
        end_failed(rt, job_id, record.run.id if record is not None and not record.lost else None, exc,
                   worker_id=None)
        return "failed"
    pending = 0
    for chunk in chunks:
        if rt.chunks.exists(record.run.id, job_id, chunk.index):
            mark_chunk_done(rt, record, chunk.index, worker_id=None)
            continue
        pending += 1
        _defer(context.app, TASK_CHUNK, f"chunk:{job_id}:{chunk.index}", PRIORITY_CHUNK,
               job_id=job_id, index=chunk.index)
    if pending == 0:
        _defer(context.app, TASK_ASSEMBLE, f"assemble:{job_id}", PRIORITY_HIGH, job_id=job_id)
    return f"{len(chunks)} chunks, {pending} deferred"


@blueprint.task(name=TASK_CHUNK, retry=_RETRY, pass_context=True)
def run_chunk(context: procrastinate.JobContext, job_id: int, index: int) -> str:
    """Compute one chunk's result file (unless it exists) and mark the chunk done."""
    rt = runtime_of(context)
    record = load_job(rt.db, job_id)
    if record.lost:
        if record.job is not None:
            remove_files_if_deleted(rt, record.job.run_id)
        return "lost"
    if (why := record.not_running()) is not None:
        finalize_cancels(rt)
        discard_job_files(rt, record.run.id)
        return why
    run_id = record.run.id
    t0 = time.perf_counter()
    if not rt.chunks.exists(run_id, job_id, index):
        spec = queue.job_chunk_specs(rt.db, job_id).get(index)
        if spec is None:
            return "unknown chunk"
        if queue.mark_chunk(rt.db, job_id, index, ChunkStatus.RUNNING, worker_id=None) is None:
            return "job not running"
        run_path = record.run_path(rt.store)
        settings = record.settings
        chunk = ChunkSpec.from_dict(spec)
        watch = _CancelWatch(rt, job_id)
        try:
            rt.chunks.write(
                run_id, job_id, index,
                lambda out: process_chunk(run_path, settings, chunk, out, should_cancel=watch),
            )
        except PipelineCancelled:
            if rt.stopping.is_set():
                raise WorkerShutdown(f"chunk {index} of job {job_id} interrupted by shutdown") from None
            finalize_cancels(rt)
            discard_job_files(rt, run_id)
            return "cancelled"
        except Exception as exc:
            if _is_transient(exc):
                raise
            queue.mark_chunk(rt.db, job_id, index, ChunkStatus.FAILED, worker_id=None)
            end_failed(rt, job_id, run_id, exc, worker_id=None)
            return "failed"
    compute_s = time.perf_counter() - t0
    if mark_chunk_done(rt, record, index, worker_id=None) is None:
        discard_job_files(rt, run_id)  # the job ended while this chunk was computed: its file goes too
        return "job not running"
    done, total = queue.chunk_progress(rt.db, job_id)
    log.info("job %s chunk %s done in %.2f s (%d/%d)", job_id, index, compute_s, done, total)
    if done == total:
        _defer(context.app, TASK_ASSEMBLE, f"assemble:{job_id}", PRIORITY_HIGH, job_id=job_id)
    return f"chunk {index} done in {compute_s:.2f} s ({done}/{total})"


@blueprint.task(name=TASK_ASSEMBLE, retry=_RETRY, pass_context=True)
def assemble_job(context: procrastinate.JobContext, job_id: int) -> str:
    """Fan the assembly of a job out: one :func:`store_wheel` task per wheel."""
    rt = runtime_of(context)
    record = load_job(rt.db, job_id)
    if (why := record.not_running()) is not None:
        return why
    indices = sorted(queue.job_chunk_specs(rt.db, job_id))
    if not indices or not all(rt.chunks.exists(record.run.id, job_id, i) for i in indices):
        return "chunks missing"
    wheels = record.wheels
    for wheel in wheels:
        _defer(context.app, TASK_STORE_WHEEL, f"store:{job_id}:{wheel}", PRIORITY_HIGH,
               job_id=job_id, wheel=wheel)
    if not wheels:
        _defer(context.app, TASK_PUBLISH, f"publish:{job_id}", PRIORITY_HIGH, job_id=job_id)
    return f"{len(wheels)} wheel(s) deferred"


T = TypeVar("T")


class _JobFailed(Exception):
    """The job was ended as failed by :func:`_on_chunks` (its task returns ``"failed"``)."""


def _on_chunks(rt: Any, job_id: int, run_id: int, work: Callable[[list[Path]], T]) -> tuple[list[int], T]:
    """``work`` on local copies of the job's chunk files (indices in order, and its result).

    A transient error (database, connection) is raised for the task's retry; any other ends the job
    as failed (:func:`end_failed`) and raises :class:`_JobFailed`.
    """
    indices = sorted(queue.job_chunk_specs(rt.db, job_id))
    try:
        with rt.chunks.local_copies(run_id, job_id, indices) as paths:
            return indices, work(paths)
    except Exception as exc:
        if _is_transient(exc):
            raise
        end_failed(rt, job_id, run_id, exc, worker_id=None)
        raise _JobFailed from exc


@blueprint.task(name=TASK_STORE_WHEEL, retry=_RETRY, pass_context=True)
def store_wheel(context: procrastinate.JobContext, job_id: int, wheel: str) -> str:
    """Assemble one wheel from the chunk files and store its rows (not yet published).

    The rows are written in one transaction (replacing the job's earlier
    rows of the wheel), then the wheel's OOR result as the job file
    ``wheel-<wheel>.json``: its presence means the wheel is stored. The
    task that finds every wheel stored defers :func:`publish_job`.
    """
    rt = runtime_of(context)
    record = load_job(rt.db, job_id)
    if (why := record.not_running()) is not None:
        return why
    run_id = record.run.id
    if wheel not in record.wheels:
        return f"run {run_id} has no wheel {wheel!r}"
    name = _WHEEL_FILE.format(wheel=wheel)
    if not rt.chunks.exists_named(run_id, job_id, name):
        t0 = time.perf_counter()
        try:
            _, done = _on_chunks(rt, job_id, run_id, lambda paths: wheel_assembly(record.settings, paths, wheel))
        except _JobFailed:
            return "failed"
        t1 = time.perf_counter()  # done None: no data of the wheel
        if done is not None and not publish.store_wheel_rows(rt.db, job_id, run_id, done.profiles):
            return "job not running"
        t2 = time.perf_counter()
        record_ = {"result": None if done is None else done.result,
                   "resolution_m": None if done is None else done.resolution_m,
                   "rows": 0 if done is None else len(done.profiles),
                   "assemble_s": round(t1 - t0, 3),
                   "store_s": round(t2 - t1, 3)}
        rt.chunks.write_bytes(run_id, job_id, name, json.dumps(jsonable(record_)).encode())
        log.info("job %s wheel %s: assembled in %.2f s, %d rows stored in %.2f s",
                 job_id, wheel, t1 - t0, record_["rows"], t2 - t1)
    if all(rt.chunks.exists_named(run_id, job_id, _WHEEL_FILE.format(wheel=w)) for w in record.wheels):
        _defer(context.app, TASK_PUBLISH, f"publish:{job_id}", PRIORITY_HIGH, job_id=job_id)
    return f"wheel {wheel} stored"


@blueprint.task(name=TASK_PUBLISH, retry=_RETRY, pass_context=True)
def publish_job(context: procrastinate.JobContext, job_id: int) -> str:
    """Publish a job whose wheels are all stored: wheel rows, old rows dropped, job done.

    First the run's results as the local worker ends them (:func:`_finish`: the track impacts
    found in the chunk files and bridged in the stored rows, the step estimate, the wheel flats,
    ``meta["track_impacts"]``); then one transaction (:func:`app.publish.publish_job`) that also
    replaces the job's rows with the bridged ones where there is a track impact, guarded by the
    job's state: a second publish of a done job changes nothing, and a publish that did not commit
    is computed again from the same stored rows and chunk files.
    """
    rt = runtime_of(context)
    record = load_job(rt.db, job_id)
    if (why := record.not_running()) is not None:
        return why
    run_id = record.run.id
    stored_wheels = []
    for wheel in record.wheels:
        name = _WHEEL_FILE.format(wheel=wheel)
        if not rt.chunks.exists_named(run_id, job_id, name):
            return f"wheel {wheel} not stored yet"
        stored_wheels.append(json.loads(rt.chunks.read_bytes(run_id, job_id, name)))
    t0 = time.perf_counter()
    try:
        indices, (results, bridged) = _on_chunks(rt, job_id, run_id,
                                                 lambda paths: _finish(rt, record, paths, stored_wheels))
    except _JobFailed:
        return "failed"
    t1 = time.perf_counter()
    meta = job_meta(
        record.settings, len(indices), worker_id=record.job.worker_id, run_sha256=record.run.sha256, mode=_MODE,
        warnings=results.meta["warnings"], track_impacts=results.meta["track_impacts"],
        assemble_s=sum(r["assemble_s"] for r in stored_wheels) + (t1 - t0),
        store_s=sum(r["store_s"] for r in stored_wheels),
    )
    stored = end_published(rt, record, results.profiles if bridged else None, results.wheels, meta, worker_id=None)
    log.info("job %s %s in %.2f s (%d rows%s)", job_id, "published" if stored else "not published (not running)",
             time.perf_counter() - t1, sum(r["rows"] for r in stored_wheels), ", rewritten bridged" if bridged else "")
    return "published" if stored else "not running any more"


def _finish(rt: WorkerRuntime, record: JobRecord, chunk_paths: Sequence[Path],
            stored_wheels: Sequence[dict[str, Any]]) -> tuple[RunResults, bool]:
    """The job's results from its stored wheels (:func:`app.pipeline.finish_assembly`, as the local
    worker ends), and whether its rows must be written again (track impacts bridged in them).

    The wheels' rows are read back as :func:`store_wheel` stored them. Without a track impact they are
    already the results (each wheel's step estimate is that of its own ``sleeper_amp``), and stay; with
    one, the publish transaction replaces them with the bridged rows. A wheel file written before the
    wheels' resolutions were kept in it: the wheel's resolution is assembled again from the chunk files.
    """
    settings = record.settings
    wheels, resolutions = [], {}
    for r in stored_wheels:
        if r["result"] is None:
            continue
        wheel = str(r["result"]["wheel"])
        wheels.append(r["result"])
        res_m = r.get("resolution_m")
        if res_m is None:
            again = wheel_assembly(settings, chunk_paths, wheel)
            res_m = None if again is None else again.resolution_m
        if res_m is not None:
            resolutions[wheel] = float(res_m)
    with rt.db.read() as session:
        profiles = job_profile_frame(session, record.job.id)
    results = finish_assembly(settings, chunk_paths, profiles, wheels, resolutions)
    return results, bool(results.meta["track_impacts"])


class _CancelWatch:
    """``should_cancel`` of a running chunk: job cancelled/finished/deleted, or shutdown.

    Polls the job row at most every ``_CANCEL_POLL_S`` seconds; a failed poll
    (database restarting) does not stop the chunk.
    """

    def __init__(self, rt: WorkerRuntime, job_id: int) -> None:
        self.rt, self.job_id = rt, job_id
        self._next = 0.0
        self._stop = False

    def __call__(self) -> bool:
        if self.rt.stopping.is_set():
            return True
        now = time.monotonic()
        if not self._stop and now >= self._next:
            self._next = now + _CANCEL_POLL_S
            try:
                self._stop = load_job(self.rt.db, self.job_id).not_running() is not None
            except Exception as exc:  # noqa: BLE001 - database away: keep computing
                log.warning("cannot check job %s for cancel: %s", self.job_id, exc)
        return self._stop
