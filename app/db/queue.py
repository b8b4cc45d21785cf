"""The job queue in SQL: claiming, heartbeats, chunk bookkeeping, marking jobs final.

Used by the local worker (embedded mode) and, with ``worker_id=None`` (any
owner) plus the fan-out functions at the end, by the Procrastinate tasks of
the production mode (:mod:`worker.tasks`); both go through the job steps of
:mod:`worker.steps`. Every change that a worker makes to a job is guarded by
``worker_id = <me> AND status = 'running'``: a worker that lost its job
(cancelled, run deleted, or claimed by another worker after the heartbeat went
stale) changes nothing and learns so from the return value. The functions
both modes call take the owner as the keyword-only ``worker_id``.

Progress is derived from the chunk rows (done / all), never from a counter,
so a repeated chunk cannot count twice. Results are published by
:func:`app.publish.publish_job`, which guards the job with :func:`owned` and marks
it done with :func:`mark_done` in its transaction.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import and_, case, func, literal, or_, select, update
from sqlalchemy.orm import Session

from app.core.i18n import N_, Msg, stored_message
from app.core.jsonable import jsonable
from app.db import results_writer
from app.db.models import ChunkStatus, Job, JobChunk, JobStatus, Run, UTCDateTime, utcnow
from app.db.session import Database

__all__ = [
    "Lease",
    "claim_next_job",
    "heartbeat",
    "release_job",
    "record_chunks",
    "mark_chunk",
    "finish_job",
    "owned",
    "mark_done",
    "FANOUT_OWNER_PREFIX",
    "queued_job_ids",
    "claim_for_fanout",
    "finalize_cancel_requests",
    "chunk_progress",
    "job_chunk_specs",
]


@dataclass(frozen=True)
class Lease:
    """State of a worker's hold on a job after a heartbeat.

    Attributes
    ----------
    owned : bool
        The job is still running under this worker.
    cancel_requested : bool
        A user asked to cancel the job.
    """

    owned: bool
    cancel_requested: bool


def _now_literal(now: dt.datetime):
    return literal(now, UTCDateTime())


def _start_values(worker_id: str, now: dt.datetime) -> dict[str, Any]:
    """Column values of a job that ``worker_id`` starts (claims) at ``now``."""
    return {
        "status": JobStatus.RUNNING,
        "worker_id": worker_id,
        "heartbeat_at": now,
        "started_at": func.coalesce(Job.started_at, _now_literal(now)),
        "attempts": Job.attempts + 1,
    }


def _claimable(cutoff: dt.datetime):
    return or_(
        Job.status == JobStatus.QUEUED,
        and_(
            Job.status == JobStatus.RUNNING,
            or_(Job.heartbeat_at.is_(None), Job.heartbeat_at < cutoff),
            # jobs fanned out to Procrastinate tasks recover through their tasks
            or_(Job.worker_id.is_(None), ~Job.worker_id.startswith(FANOUT_OWNER_PREFIX)),
        ),
    )


def claim_next_job(db: Database, worker_id: str, stale_after_s: float) -> int | None:
    """Claim the oldest queued job, or a running job whose worker is dead.

    A job left ``running`` with a heartbeat older than ``stale_after_s``
    seconds belongs to a dead worker and is claimed again. The claim is one
    conditional ``UPDATE`` whose row count tells whether this worker won.

    Returns
    -------
    int or None
        Id of the claimed job, or None when nothing is claimable.
    """
    if stale_after_s <= 0:
        raise ValueError(f"stale_after_s must be > 0 s, got {stale_after_s}")
    now = utcnow()
    cutoff = now - dt.timedelta(seconds=stale_after_s)
    with db.read() as session:
        candidates = session.scalars(
            select(Job.id).where(_claimable(cutoff)).order_by(Job.created_at, Job.id).limit(20)
        ).all()
    for job_id in candidates:
        with db.write() as session:
            result = session.execute(
                update(Job)
                .where(Job.id == job_id, _claimable(cutoff))
                .values(**_start_values(worker_id, now))
            )
            if result.rowcount == 1:
                return int(job_id)
    return None


def owned(job_id: int, worker_id: str | None):
    """The job is running under ``worker_id``; ``None`` = under any owner.

    The local worker owns a whole job (its ``worker_id``). In the fan-out mode
    (Procrastinate, :mod:`worker.tasks`) many workers run the chunks of one
    job at once: they pass ``None`` and are guarded by the job's status only.
    """
    if worker_id is None:
        return and_(Job.id == job_id, Job.status == JobStatus.RUNNING)
    return and_(Job.id == job_id, Job.worker_id == worker_id, Job.status == JobStatus.RUNNING)


def heartbeat(db: Database, job_id: int, worker_id: str) -> Lease:
    """Refresh the heartbeat of a job this worker runs; report ownership and cancel."""
    with db.write() as session:
        result = session.execute(
            update(Job).where(owned(job_id, worker_id)).values(heartbeat_at=utcnow())
        )
        if result.rowcount != 1:
            return Lease(owned=False, cancel_requested=False)
        cancel = session.scalar(select(Job.cancel_requested).where(Job.id == job_id))
        return Lease(owned=True, cancel_requested=bool(cancel))


def release_job(db: Database, job_id: int, worker_id: str) -> bool:
    """Put a job this worker runs back in the queue (graceful worker shutdown)."""
    with db.write() as session:
        result = session.execute(
            update(Job)
            .where(owned(job_id, worker_id))
            .values(status=JobStatus.QUEUED, worker_id=None, heartbeat_at=None)
        )
        return result.rowcount == 1


def record_chunks(
    db: Database, job_id: int, specs: Sequence[tuple[int, dict[str, Any]]], *, worker_id: str
) -> bool:
    """Record the planned chunks of a job (idempotent: existing rows are kept).

    Parameters
    ----------
    specs : sequence of (int, dict)
        Chunk index and its JSON-serialisable spec (``ChunkSpec.to_dict()``).
    worker_id : str
        Owner of the job (the local worker, or the fan-out planner).

    Returns
    -------
    bool
        False if the job is no longer owned by this worker.
    """
    with db.write() as session:
        result = session.execute(
            update(Job)
            .where(owned(job_id, worker_id))
            .values(n_chunks=len(specs), heartbeat_at=utcnow())
        )
        if result.rowcount != 1:
            return False
        existing = set(
            session.scalars(select(JobChunk.chunk_index).where(JobChunk.job_id == job_id)).all()
        )
        for index, spec in specs:
            if index not in existing:
                session.add(
                    JobChunk(
                        job_id=job_id, chunk_index=index, status=ChunkStatus.PENDING, spec=spec
                    )
                )
        return True


def mark_chunk(
    db: Database,
    job_id: int,
    index: int,
    status: str,
    result_path: str | None = None,
    *,
    worker_id: str | None,
) -> float | None:
    """Set the status of a chunk and update the job's progress.

    Parameters
    ----------
    result_path : str, optional
        Where the chunk's result is (store-relative path or URL).
    worker_id : str or None
        Owner of the job; None: any owner (fan-out mode).

    Returns
    -------
    float or None
        The job's progress (done chunks / all chunks), or None if the job is
        no longer owned by this worker.
    """
    if status not in (ChunkStatus.PENDING, ChunkStatus.RUNNING, ChunkStatus.DONE, ChunkStatus.FAILED):
        raise ValueError(f"status: unknown chunk status {status!r}")
    now = utcnow()
    with db.write() as session:
        beat = session.execute(
            update(Job).where(owned(job_id, worker_id)).values(heartbeat_at=now)
        )
        if beat.rowcount != 1:
            return None
        values: dict[str, Any] = {"status": status}
        if status == ChunkStatus.RUNNING:
            values["started_at"] = now
        if status in (ChunkStatus.DONE, ChunkStatus.FAILED):
            values["finished_at"] = now
        if result_path is not None:
            values["result_path"] = result_path
        stmt = update(JobChunk).where(JobChunk.job_id == job_id, JobChunk.chunk_index == index)
        if status == ChunkStatus.DONE:
            # a chunk found done again (resumed job) keeps its first finish time
            stmt = stmt.where(JobChunk.status != ChunkStatus.DONE)
        session.execute(stmt.values(**values))
        total, done = session.execute(
            select(
                func.count(),
                func.coalesce(func.sum(case((JobChunk.status == ChunkStatus.DONE, 1), else_=0)), 0),
            ).where(JobChunk.job_id == job_id)
        ).one()
        progress = float(done) / float(total) if total else 0.0
        # Never report 1.0 before the results are stored.
        progress = min(progress, 0.999)
        session.execute(update(Job).where(Job.id == job_id).values(progress=progress))
        return progress


#: the error text of a job cancelled on request (the API answers it in the reader's language)
CANCELLED_BY_REQUEST = N_("cancelled by request")


def finish_job(
    db: Database, job_id: int, status: str, error: str | None = None, *, worker_id: str | None,
    message: str | None = None,
) -> bool:
    """Mark a job this worker runs as failed or cancelled (with its error text).

    ``worker_id``: owner of the job; None: any owner (fan-out mode). ``message``: the error marked for
    translation (:class:`~app.core.i18n.Msg`), kept in the job's ``meta`` (``error_message``) so that
    the API answers it in the reader's language (``error`` stays the text, cut to the column).
    """
    if status not in (JobStatus.FAILED, JobStatus.CANCELLED):
        raise ValueError(f"status must be failed or cancelled, got {status!r}")
    with db.write() as session:
        result = session.execute(
            update(Job)
            .where(owned(job_id, worker_id))
            .values(status=status, error=error, finished_at=utcnow(), heartbeat_at=None)
        )
        if result.rowcount != 1:
            return False
        if isinstance(message, Msg):
            meta = dict(session.execute(select(Job.meta).where(Job.id == job_id)).scalar_one() or {})
            meta["error_message"] = stored_message(message)
            session.execute(update(Job).where(Job.id == job_id).values(meta=meta))
        results_writer.discard_profile_rows(session, job_id)  # rows of wheels stored before it ended
        return True


def mark_done(session: Session, job_id: int, meta: dict[str, Any]) -> None:
    """Mark a job done with its provenance ``meta``, in the caller's transaction (the publish step's,
    which checked first that the job is still :func:`owned`)."""
    session.execute(
        update(Job)
        .where(Job.id == job_id)
        .values(
            status=JobStatus.DONE,
            progress=1.0,
            error=None,
            meta=jsonable(meta),
            finished_at=utcnow(),
            heartbeat_at=None,
        )
    )


# --- fan-out mode (Procrastinate tasks, worker/tasks.py) ----------------------
#: prefix of ``jobs.worker_id`` for jobs run by the fan-out tasks
FANOUT_OWNER_PREFIX = "procrastinate:"


def queued_job_ids(db: Database, limit: int = 100) -> list[int]:
    """Ids of queued jobs, oldest first (at most ``limit``)."""
    if limit < 1:
        raise ValueError(f"limit must be >= 1, got {limit}")
    with db.read() as session:
        rows = session.scalars(
            select(Job.id)
            .where(Job.status == JobStatus.QUEUED)
            .order_by(Job.created_at, Job.id)
            .limit(limit)
        ).all()
    return [int(r) for r in rows]


def line_has_active_jobs(db: Database, line_id: str, track: str | None, *, besides: int | None = None) -> bool:
    """Whether a job of a run on ``line_id`` (and ``track``, if given) is queued or running (other than job
    ``besides``).

    The worker refreshes a line's reference curves after the publish of the line's last such job only
    (:func:`worker.steps.refresh_line_reference`): a history uploaded at once refits them once, not once per
    run (each refit reads every run of the line).
    """
    query = (select(Job.id).join(Run, Run.id == Job.run_id)
             .where(Job.status.in_(JobStatus.ACTIVE), Run.line_id == line_id))
    if track is not None:
        query = query.where(Run.track == track)
    if besides is not None:
        query = query.where(Job.id != besides)
    with db.read() as session:
        return session.scalar(query.limit(1)) is not None


def claim_for_fanout(db: Database, job_id: int, owner: str) -> bool:
    """Start a queued job under ``owner`` (the planning task); idempotent for that owner.

    Returns True if the job was queued and is now running under ``owner``, or
    was already running under ``owner`` (a retry of the same planning task);
    False otherwise (another planner won, or the job was cancelled/deleted).
    """
    if not owner.startswith(FANOUT_OWNER_PREFIX):
        raise ValueError(f"owner must start with {FANOUT_OWNER_PREFIX!r}, got {owner!r}")
    now = utcnow()
    with db.write() as session:
        result = session.execute(
            update(Job)
            .where(Job.id == job_id, Job.status == JobStatus.QUEUED)
            .values(**_start_values(owner, now))
        )
        if result.rowcount == 1:
            return True
        row = session.execute(select(Job.status, Job.worker_id).where(Job.id == job_id)).one_or_none()
        return row is not None and row[0] == JobStatus.RUNNING and row[1] == owner


def finalize_cancel_requests(db: Database) -> dict[int, int]:
    """Mark running fan-out jobs with a cancel request as cancelled.

    Their chunk tasks see the job is no longer running at their next check
    (between sub-blocks) and stop.

    Returns
    -------
    dict
        Job id → run id of the jobs cancelled now.
    """
    with db.write() as session:
        rows = session.execute(
            update(Job)
            .where(
                Job.status == JobStatus.RUNNING,
                Job.cancel_requested.is_(True),
                Job.worker_id.startswith(FANOUT_OWNER_PREFIX),
            )
            .values(
                status=JobStatus.CANCELLED,
                error=CANCELLED_BY_REQUEST,
                finished_at=utcnow(),
                heartbeat_at=None,
            )
            .returning(Job.id, Job.run_id)
        ).all()
        for job_id, _ in rows:
            results_writer.discard_profile_rows(session, job_id)  # rows of wheels stored before the cancel
        return {int(job_id): int(run_id) for job_id, run_id in rows}


def chunk_progress(db: Database, job_id: int) -> tuple[int, int]:
    """(done chunks, all chunks) of a job, counted from its chunk rows."""
    with db.read() as session:
        total, done = session.execute(
            select(
                func.count(),
                func.coalesce(func.sum(case((JobChunk.status == ChunkStatus.DONE, 1), else_=0)), 0),
            ).where(JobChunk.job_id == job_id)
        ).one()
    return int(done), int(total)


def job_chunk_specs(db: Database, job_id: int) -> dict[int, dict[str, Any]]:
    """Planned chunks of a job: ``{chunk_index: spec}``."""
    with db.read() as session:
        rows = session.execute(
            select(JobChunk.chunk_index, JobChunk.spec).where(JobChunk.job_id == job_id)
        ).all()
    return {int(i): dict(spec) for i, spec in rows}
