"""The job lifecycle both worker modes share: load, plan, mark, fail, describe.

The local job loop (:mod:`worker.runner`: one worker runs a whole job) and the
Procrastinate tasks (:mod:`worker.tasks`: a job fanned out over many workers)
take a job through the same steps, written once here:

* :class:`WorkerRuntime`: what the steps of one worker process share (service
  settings, database, run store, :class:`~worker.chunkstore.ChunkStore`, stop flag);
* :func:`load_job`: the job, its run and its processing settings;
* :func:`record_plan`: plan a claimed job's chunks, record their rows and
  discard half-written files of an earlier attempt;
* :func:`mark_chunk_done`: record a chunk whose result is stored;
* :func:`fail_job`: a job failed, with its error text;
* :func:`remove_files_if_deleted`: the files a late step wrote for a deleted run;
* :func:`discard_job_files`: the chunk and wheel files of a run's jobs that are
  done, failed or cancelled (a job's files are kept only while it is queued or
  running: the published rows are in SQL, a failed or cancelled job is never
  resumed), here and in the shared store; called at every such end;
* :func:`job_meta`: the provenance stored with the results (pipeline and
  worker metadata, ``meta["worker"]``);
* :func:`refresh_line_reference`: after a publish, recompute the reference
  curves of the run's line (stiffness index; :mod:`app.analytics.reference_curves`)
  when no other job of the line is queued or running.

The ends of a job, one function each: :func:`end_published` (the publish step,
:func:`app.publish.publish_job`, then the files go and the line's curves are
refreshed), :func:`end_failed` (marked failed, files gone) and :func:`end_cancelled`.

Every write goes through :mod:`app.db.queue` (and the publish step), guarded by the job's owner:
``worker_id`` is the local worker's id, or None for the fan-out tasks (any
owner; guarded by the job's state only).
"""

from __future__ import annotations

import logging
import threading
import traceback
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from app import publish
from app.analysis.settings import ProcessingSettings
from app.analytics.reference_curves import CurveParams, refresh_reference
from app.condition.config import ConditionConfig
from app.core.runstore import RunStore
from app.db import crud, queue
from app.db.models import ChunkStatus, Job, JobStatus, Run
from app.db.session import Database
from app.io import WHEELS
from app.pipeline import ChunkSpec, plan_chunks, results_meta
from app.places.config import FollowupPolicy, PlacesConfig
from app.runs import jobs
from app.settings import Settings
from worker.chunkstore import ChunkStore

__all__ = [
    "WorkerRuntime",
    "JobRecord",
    "load_job",
    "record_plan",
    "mark_chunk_done",
    "fail_job",
    "remove_files_if_deleted",
    "discard_job_files",
    "finalize_cancels",
    "job_meta",
    "refresh_line_reference",
    "end_published",
    "end_failed",
    "end_cancelled",
]

log = logging.getLogger(__name__)

#: longest error text stored with a failed job, characters
_MAX_ERROR_CHARS = 4000


class WorkerRuntime:
    """What the job steps of one worker process share.

    Parameters
    ----------
    settings : Settings
        Service settings (database, run store, shared store, intervals).
    db : Database, optional
        Database to use; created from ``settings.database_url`` on first use
        if omitted.

    Attributes
    ----------
    store : RunStore
        The run store (run files; fetched from the shared store if need be).
    chunks : ChunkStore
        Where the chunk results of jobs live.
    stopping : threading.Event
        Set when the worker process shuts down: running chunks stop at their
        next sub-block.
    condition : ConditionConfig
        How published runs become segment condition rows (from the settings).
    places : PlacesConfig
        How published runs' places are found and followed (from the settings).
    places_followup : FollowupPolicy
        How the places follow-up of a publish is retried (from the settings).
    """

    def __init__(self, settings: Settings, db: Database | None = None) -> None:
        self.settings = settings
        self._db = db
        self.store = RunStore(settings.run_store, settings.shared_store)
        self.chunks = ChunkStore(self.store)
        self.stopping = threading.Event()
        self.condition = ConditionConfig.from_settings(settings)
        self.places = PlacesConfig.from_settings(settings)
        self.places_followup = FollowupPolicy.from_settings(settings)

    @property
    def db(self) -> Database:
        """The database (connected on first use)."""
        if self._db is None:
            self._db = Database(self.settings.database_url)
        return self._db

    def close(self) -> None:
        """Close the database connections, if any were opened."""
        if self._db is not None:
            self._db.dispose()


@dataclass(frozen=True)
class JobRecord:
    """A job and its run as read from the database (either None when gone).

    Attributes
    ----------
    job : Job or None
    run : Run or None
    """

    job: Job | None
    run: Run | None

    @property
    def lost(self) -> bool:
        """Whether the job or its run no longer exists (deleted)."""
        return self.job is None or self.run is None

    @property
    def settings(self) -> ProcessingSettings:
        """The job's processing settings (ValueError if they are invalid; job not lost)."""
        return ProcessingSettings.from_stored(self.job.settings)

    @property
    def wheels(self) -> list[str]:
        """The wheels whose acceleration channel the run has."""
        channels = (self.run.channels or []) if self.run is not None else []
        return [w for w in WHEELS if f"Z{w}" in channels]

    def not_running(self) -> str | None:
        """Why the job's work should stop (``"lost"``, ``"job <status>"``), or None."""
        if self.lost:
            return "lost"
        if self.job.status != JobStatus.RUNNING or self.job.cancel_requested:
            return f"job {self.job.status}"
        return None

    def run_path(self, store: RunStore) -> Path:
        """The run's canonical file on this host (fetched from the shared store if need be; run not lost)."""
        return store.local_file(self.run.file_path)


def load_job(db: Database, job_id: int) -> JobRecord:
    """Read job ``job_id`` and its run."""
    with db.read() as session:
        job = crud.get_job(session, job_id)
        run = crud.get_run(session, job.run_id) if job is not None else None
    return JobRecord(job, run)


def record_plan(
    rt: WorkerRuntime, record: JobRecord, run_path: Path, *, worker_id: str
) -> list[ChunkSpec] | None:
    """Plan the chunks of a claimed job and record their rows (idempotent).

    Half-written files of an earlier attempt are removed from the job's
    directory (finished chunk files are kept: those chunks are not computed
    again).

    Parameters
    ----------
    rt : WorkerRuntime
    record : JobRecord
        The job (not lost).
    run_path : Path
        The run's canonical file on this host.
    worker_id : str
        Owner of the job: the local worker's id or the fan-out planner's.

    Returns
    -------
    list of ChunkSpec or None
        The chunks, or None if the job is no longer ``worker_id``'s.
    """
    chunks = plan_chunks(run_path, record.settings)
    specs = [(c.index, c.to_dict()) for c in chunks]
    if not queue.record_chunks(rt.db, record.job.id, specs, worker_id=worker_id):
        return None
    rt.chunks.discard_partial(record.run.id, record.job.id)
    return chunks


def mark_chunk_done(rt: WorkerRuntime, record: JobRecord, index: int, *, worker_id: str | None) -> float | None:
    """Record chunk ``index`` of a job as done, with where its result is.

    Returns
    -------
    float or None
        The job's progress, or None if the job is no longer ``worker_id``'s
        (None: any owner) or not running.
    """
    where = rt.chunks.location(record.run.id, record.job.id, index)
    return queue.mark_chunk(rt.db, record.job.id, index, ChunkStatus.DONE, where, worker_id=worker_id)


def fail_job(db: Database, job_id: int, exc: BaseException, *, worker_id: str | None) -> bool:
    """Mark a job failed with the text of ``exc`` (its traceback goes to the log).

    Returns
    -------
    bool
        False if the job is no longer ``worker_id``'s (None: any owner) or not running.
    """
    log.error("job %s failed:\n%s", job_id, "".join(traceback.format_exception(exc)))
    message = jobs.failure_message(exc)
    error = str(message)
    return queue.finish_job(db, job_id, JobStatus.FAILED, error[:_MAX_ERROR_CHARS], worker_id=worker_id,
                            message=message if len(error) <= _MAX_ERROR_CHARS else None)


def remove_files_if_deleted(rt: WorkerRuntime, run_id: int) -> bool:
    """Remove the files of run ``run_id`` (the shared store's too) if the run was deleted.

    A step that was running while its run was deleted may have written files
    after the deletion removed the run's directory.

    Returns
    -------
    bool
        True if the run is deleted (its files are removed now).
    """
    with rt.db.read() as session:
        if crud.get_run(session, run_id) is not None:
            return False
    rt.store.remove_run(run_id)
    return True


def discard_job_files(rt: WorkerRuntime, run_id: int) -> list[int]:
    """Remove the files of run ``run_id``'s jobs that are no longer queued or running.

    Called when a job of the run is published, fails or is cancelled: its own
    files go, and so do those of older jobs it supersedes or that ended
    without a worker (a queued job cancelled through the API). Nothing that
    a queued or running job may still need is touched (a job put back in the
    queue by a worker's shutdown resumes from its chunk files). A failure to
    remove is logged, never raised: the job's outcome is recorded already.

    Returns
    -------
    list of int
        The jobs whose files were removed.
    """
    try:
        ids = rt.store.job_ids_with_files(run_id)
        if not ids:
            return []
        with rt.db.read() as session:
            active = {
                job_id for job_id in ids
                if (job := crud.get_job(session, job_id)) is not None
                and job.run_id == run_id
                and job.status in (JobStatus.QUEUED, JobStatus.RUNNING)
            }
        gone = [job_id for job_id in ids if job_id not in active]
        for job_id in gone:
            rt.store.remove_job_files(run_id, job_id)
    except Exception:  # noqa: BLE001 - clean-up only: retried at the run's next job end
        log.exception("cannot remove the finished job files of run %s", run_id)
        return []
    if gone:
        log.info("run %s: removed the files of finished job(s) %s", run_id, gone)
    return gone


def finalize_cancels(rt: WorkerRuntime) -> int:
    """Mark the fan-out jobs with a cancel request cancelled and remove their files.

    Returns
    -------
    int
        Number of jobs cancelled now.
    """
    cancelled = queue.finalize_cancel_requests(rt.db)
    for run_id in sorted(set(cancelled.values())):
        discard_job_files(rt, run_id)
    return len(cancelled)


def job_meta(
    settings: ProcessingSettings,
    n_chunks: int,
    *,
    worker_id: str | None,
    run_sha256: str,
    mode: str | None = None,
    warnings: Sequence[str] = (),
    track_impacts: Sequence[dict[str, Any]] | None = None,
    **seconds: float,
) -> dict[str, Any]:
    """Provenance stored with a job's results.

    Parameters
    ----------
    settings : ProcessingSettings
    n_chunks : int
    worker_id : str or None
        Who ran the job (the local worker, or the fan-out owner).
    run_sha256 : str
        Hash of the run file the results come from.
    mode : str, optional
        ``"procrastinate"`` for the fan-out mode (the local mode says none).
    warnings : sequence of str
        The results' warnings (:func:`app.pipeline.run_warnings`), shown with the job.
    track_impacts : sequence of dict, optional
        The run's track impacts with their masks (:func:`app.pipeline.impacts.impacts_meta`), kept as
        ``track_impacts``: the condition store leaves the masked bins out.
    **seconds : float
        Timings, s (``compute_s``; ``assemble_s``, ``store_s``), rounded to ms.

    Returns
    -------
    dict
        :func:`app.pipeline.results_meta` plus ``"worker"``.
    """
    worker: dict[str, Any] = {"worker_id": worker_id}
    if mode is not None:
        worker["mode"] = mode
    worker["n_chunks"] = n_chunks
    worker.update({name: round(value, 3) for name, value in seconds.items()})
    worker["run_sha256"] = run_sha256
    out = {**results_meta(settings, n_chunks, warnings), "worker": worker}
    if track_impacts is not None:
        out["track_impacts"] = list(track_impacts)
    return out


def refresh_line_reference(rt: WorkerRuntime, run: Run | None, *, job_id: int | None = None) -> None:
    """Recompute the reference curves of the stiffness index of ``run``'s line (after a publish of job
    ``job_id``), unless another job of the line is queued or running: its publish refreshes them (a history
    uploaded at once refits them once, not once per run; each refit reads every run of the line).

    Best effort: the job's results are already published, so a failure is only
    logged (the API computes stale curves on demand).
    """
    if run is None or run.line_id is None:
        return
    try:
        if queue.line_has_active_jobs(rt.db, run.line_id, run.track, besides=job_id):
            log.info("reference curves of line %s track %s left to the line's next publish", run.line_id, run.track)
            return
        stored = refresh_reference(rt.db, run.line_id, run.track, CurveParams.from_settings(rt.settings))
    except Exception:  # noqa: BLE001 - never fail a published job for its reference curves
        log.exception("reference curves of line %s track %s not refreshed", run.line_id, run.track)
        return
    if stored is not None:
        log.info("reference curves of line %s track %s refreshed from %d runs in %.2f s",
                 run.line_id, run.track, len(stored.run_ids), stored.compute_s)


def end_published(rt: WorkerRuntime, record: JobRecord, profiles: Any, wheels: Sequence[dict[str, Any]],
                  meta: dict[str, Any], *, worker_id: str | None) -> bool:
    """Publish a job's results (:func:`app.publish.publish_job`: results, condition rows and alerts
    with the job marked done, one transaction; then the places follow-up of the run's line in
    transactions of its own), then remove the run's finished job files and, if published, refresh
    the reference curves of its line.

    ``profiles``: the job's profile rows, or None when stored wheel by wheel (fan-out).

    Returns
    -------
    bool
        True if published; False if the job is no longer ``worker_id``'s, a cancel was
        requested, or the run was deleted.
    """
    run_id = record.run.id
    stored = publish.publish_job(rt.db, record.job.id, run_id, profiles, wheels, meta, worker_id=worker_id,
                                 condition=rt.condition, places=rt.places, places_followup=rt.places_followup)
    discard_job_files(rt, run_id)  # its chunk (and wheel) files, and those of the jobs it supersedes
    if stored:
        refresh_line_reference(rt, record.run, job_id=record.job.id)
    return stored


def end_failed(rt: WorkerRuntime, job_id: int, run_id: int | None, exc: BaseException, *,
               worker_id: str | None) -> bool:
    """Mark a job failed with the text of ``exc`` (:func:`fail_job`) and remove the run's finished
    job files (``run_id`` None: the run is unknown, nothing removed); False if not ``worker_id``'s."""
    failed = fail_job(rt.db, job_id, exc, worker_id=worker_id)
    if run_id is not None:
        discard_job_files(rt, run_id)
    return failed


def end_cancelled(rt: WorkerRuntime, job_id: int, run_id: int, *, worker_id: str) -> bool:
    """Mark a job this worker runs cancelled (by request) and remove the run's finished job files."""
    cancelled = queue.finish_job(rt.db, job_id, JobStatus.CANCELLED, queue.CANCELLED_BY_REQUEST, worker_id=worker_id)
    discard_job_files(rt, run_id)
    return cancelled

