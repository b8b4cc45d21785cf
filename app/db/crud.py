"""Runs and jobs: look up, list and delete runs; queue, list and cancel jobs.

Every function takes an open :class:`~sqlalchemy.orm.Session`; the caller
decides the transaction (``Database.read()`` or ``Database.write()``). A job's
results are written by :mod:`app.db.results_writer` and read by
:mod:`app.db.results_reader`; the workers' side of the queue is
:mod:`app.db.queue`.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterable, Sequence
from typing import Any, TypeVar

from sqlalchemy import ColumnElement, and_, delete, func, select, update
from sqlalchemy.orm import Session

from app.db.condition_store import delete_run_condition
from app.db.models import Job, JobChunk, JobStatus, ProfileBin, Run, WheelOOR, utcnow

__all__ = [
    "JOBS_CHANNEL",
    "get_run",
    "get_run_by_sha256",
    "list_runs",
    "delete_run",
    "create_job",
    "get_job",
    "list_jobs",
    "latest_job",
    "latest_jobs",
    "active_job",
    "request_cancel",
    "chunk_counts",
    "queue_counts",
]

#: PostgreSQL notification channel of newly queued jobs (payload: the job id)
JOBS_CHANNEL = "trackvkf_jobs"

_Row = TypeVar("_Row", Run, Job)


def _page(
    session: Session,
    entity: type[_Row],
    conditions: Sequence[ColumnElement[bool]],
    order_by: Sequence[ColumnElement[Any]],
    limit: int,
    offset: int,
) -> tuple[list[_Row], int]:
    """One page of the rows of ``entity`` meeting all ``conditions``, and their total count."""
    if limit < 1:
        raise ValueError(f"limit must be >= 1, got {limit}")
    if offset < 0:
        raise ValueError(f"offset must be >= 0, got {offset}")
    where = and_(True, *conditions)
    total = session.scalar(select(func.count()).select_from(entity).where(where)) or 0
    rows = session.scalars(select(entity).where(where).order_by(*order_by).limit(limit).offset(offset)).all()
    return list(rows), int(total)


# --- runs -------------------------------------------------------------------
def get_run(session: Session, run_id: int) -> Run | None:
    """The run with id ``run_id``, or None."""
    return session.get(Run, run_id)


def get_run_by_sha256(session: Session, sha256: str) -> Run | None:
    """The run whose uploaded file has this sha256 (hex), or None."""
    return session.scalar(select(Run).where(Run.sha256 == sha256))


def list_runs(
    session: Session,
    *,
    line_id: str | None = None,
    vehicle_id: str | None = None,
    track: str | None = None,
    start_from: dt.datetime | None = None,
    start_to: dt.datetime | None = None,
    limit: int = 50,
    offset: int = 0,
) -> tuple[list[Run], int]:
    """Runs matching the filters, newest start first, and the total count.

    Parameters
    ----------
    line_id, vehicle_id, track : str, optional
        Exact matches.
    start_from, start_to : datetime, optional
        Start time range, inclusive (aware datetimes).
    limit, offset : int
        Page size (> 0) and offset (>= 0).
    """
    conditions = [
        column == value
        for column, value in ((Run.line_id, line_id), (Run.vehicle_id, vehicle_id), (Run.track, track))
        if value is not None
    ]
    if start_from is not None:
        conditions.append(Run.start_time >= start_from)
    if start_to is not None:
        conditions.append(Run.start_time <= start_to)
    return _page(session, Run, conditions, (Run.start_time.desc(), Run.id.desc()), limit, offset)


def delete_run(session: Session, run_id: int) -> bool:
    """Delete a run and everything that belongs to it; False if there was none.

    Children are deleted explicitly (``profile_bins`` has no foreign keys, and
    the result must not depend on foreign-key enforcement elsewhere either).
    """
    # lock the run first (as writers of results do, results_writer.lock_run_for_results): rows of a
    # job being stored now are committed before they are deleted, never left behind
    if session.scalar(select(Run.id).where(Run.id == run_id).with_for_update()) is None:
        return False
    job_ids = select(Job.id).where(Job.run_id == run_id).scalar_subquery()
    delete_run_condition(session, run_id)
    session.execute(delete(ProfileBin).where(ProfileBin.job_id.in_(job_ids)))
    session.execute(delete(WheelOOR).where(WheelOOR.run_id == run_id))
    session.execute(delete(JobChunk).where(JobChunk.job_id.in_(job_ids)))
    session.execute(delete(Job).where(Job.run_id == run_id))
    result = session.execute(delete(Run).where(Run.id == run_id))
    return result.rowcount > 0


# --- jobs -------------------------------------------------------------------
def create_job(
    session: Session, run_id: int, settings: dict[str, Any], created_by: str | None = None
) -> Job:
    """Queue a processing job for run ``run_id`` with ``settings`` (a settings dict).

    On PostgreSQL the commit also notifies :data:`JOBS_CHANNEL` with the job id,
    so that the production workers plan it at once (:mod:`worker.tasks`).
    """
    job = Job(
        run_id=run_id,
        status=JobStatus.QUEUED,
        progress=0.0,
        settings=dict(settings),
        cancel_requested=False,
        attempts=0,
        created_by=created_by,
        created_at=utcnow(),
    )
    session.add(job)
    session.flush()
    if session.get_bind().dialect.name == "postgresql":
        # delivered at commit, and only if the job is committed
        session.execute(select(func.pg_notify(JOBS_CHANNEL, str(job.id))))
    return job


def get_job(session: Session, job_id: int) -> Job | None:
    """The job with id ``job_id``, or None."""
    return session.get(Job, job_id)


def list_jobs(
    session: Session,
    *,
    run_id: int | None = None,
    status: str | None = None,
    limit: int = 50,
    offset: int = 0,
) -> tuple[list[Job], int]:
    """Jobs, newest first, optionally of one run and/or one status, and the total.

    Parameters
    ----------
    run_id : int, optional
        Jobs of this run only.
    status : str, optional
        One of :attr:`JobStatus.ALL`.
    limit, offset : int
        Page size (> 0) and offset (>= 0).
    """
    if status is not None and status not in JobStatus.ALL:
        raise ValueError(f"status must be one of {', '.join(JobStatus.ALL)}, got {status!r}")
    conditions = [
        column == value for column, value in ((Job.run_id, run_id), (Job.status, status)) if value is not None
    ]
    return _page(session, Job, conditions, (Job.id.desc(),), limit, offset)


def latest_job(session: Session, run_id: int) -> Job | None:
    """The newest job of a run, or None."""
    return session.scalar(
        select(Job).where(Job.run_id == run_id).order_by(Job.id.desc()).limit(1)
    )


def latest_jobs(session: Session, run_ids: Sequence[int]) -> dict[int, Job]:
    """The newest job of each of ``run_ids`` (runs without a job are absent)."""
    if not run_ids:
        return {}
    newest = (
        select(func.max(Job.id)).where(Job.run_id.in_(list(run_ids))).group_by(Job.run_id)
    ).scalar_subquery()
    jobs = session.scalars(select(Job).where(Job.id.in_(newest))).all()
    return {job.run_id: job for job in jobs}


def active_job(session: Session, run_id: int) -> Job | None:
    """The queued or running job of a run, or None."""
    return session.scalar(
        select(Job)
        .where(Job.run_id == run_id, Job.status.in_(JobStatus.ACTIVE))
        .order_by(Job.id.desc())
        .limit(1)
    )


def request_cancel(session: Session, job_id: int) -> str | None:
    """Cancel a job: a queued job at once, a running one at its next chunk boundary.

    Returns
    -------
    str or None
        ``"cancelled"`` (was queued), ``"requested"`` (running; the worker
        stops it), ``"final"`` (already done/failed/cancelled: nothing
        changed), or None if there is no such job.
    """
    now = utcnow()
    res = session.execute(
        update(Job)
        .where(Job.id == job_id, Job.status == JobStatus.QUEUED)
        .values(status=JobStatus.CANCELLED, cancel_requested=True, finished_at=now)
    )
    if res.rowcount:
        return "cancelled"
    res = session.execute(
        update(Job)
        .where(Job.id == job_id, Job.status == JobStatus.RUNNING)
        .values(cancel_requested=True)
    )
    if res.rowcount:
        return "requested"
    return "final" if session.get(Job, job_id) is not None else None


def chunk_counts(session: Session, job_ids: Iterable[int]) -> dict[int, dict[str, int]]:
    """Number of chunks per status for each job: ``{job_id: {status: n}}``."""
    ids = list(job_ids)
    if not ids:
        return {}
    rows = session.execute(
        select(JobChunk.job_id, JobChunk.status, func.count())
        .where(JobChunk.job_id.in_(ids))
        .group_by(JobChunk.job_id, JobChunk.status)
    ).all()
    out: dict[int, dict[str, int]] = {}
    for job_id, status, n in rows:
        out.setdefault(job_id, {})[status] = int(n)
    return out


def queue_counts(session: Session) -> dict[str, int]:
    """Number of jobs per status."""
    rows = session.execute(select(Job.status, func.count()).group_by(Job.status)).all()
    return {status: int(n) for status, n in rows}
