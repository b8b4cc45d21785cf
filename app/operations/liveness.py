"""Worker liveness and the state of the job queue, as ``/health`` and ``/metrics`` report them.

Every worker process (both modes: the local job loop and the Procrastinate
workers, each child of a supervisor too) keeps one row of ``worker_heartbeats``
fresh from a daemon thread (:class:`worker.heartbeat.HeartbeatLoop`) and
removes it when it stops. A row older than ``worker_stale_after_s`` belongs to
a worker that died without stopping (SIGKILL, power loss, host gone): it no
longer counts as alive, and rows older than a day are pruned by the next
worker that starts.

:func:`queue_health` reads the rest from the jobs table: queue depth, the age
of the oldest queued job, running jobs and the *stuck* ones (running, with a
job heartbeat older than ``health_stuck_after_s``: no worker has reported
progress on them for that long). The service is ``degraded`` when jobs wait
(queued, or running) and no worker is alive, or when a job is stuck.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

from sqlalchemy import delete, func, select, update
from sqlalchemy.orm import Session

from app.db.models import Job, JobStatus, WorkerHeartbeat, utcnow
from app.db.session import Database

__all__ = ["beat", "forget", "prune", "WorkerInfo", "QueueHealth", "queue_health", "PRUNE_AFTER"]

#: heartbeat rows of dead workers older than this are removed by a starting worker
PRUNE_AFTER = dt.timedelta(days=1)


def beat(db: Database, worker_id: str, *, host: str, pid: int, mode: str,
         now: dt.datetime | None = None) -> None:
    """Record that worker process ``worker_id`` is alive now (insert its row or refresh it)."""
    if not worker_id:
        raise ValueError("worker_id: empty")
    now = now or utcnow()
    with db.write() as session:
        result = session.execute(update(WorkerHeartbeat).where(WorkerHeartbeat.worker_id == worker_id)
                                 .values(last_seen_at=now))
        if result.rowcount == 0:
            session.add(WorkerHeartbeat(worker_id=worker_id, host=host[:255], pid=int(pid), mode=mode[:32],
                                        started_at=now, last_seen_at=now))


def forget(db: Database, worker_id: str) -> None:
    """Remove the row of a worker process that stops."""
    with db.write() as session:
        session.execute(delete(WorkerHeartbeat).where(WorkerHeartbeat.worker_id == worker_id))


def prune(db: Database, older_than: dt.timedelta = PRUNE_AFTER, now: dt.datetime | None = None) -> int:
    """Remove the rows of workers silent for longer than ``older_than``; how many."""
    cutoff = (now or utcnow()) - older_than
    with db.write() as session:
        return int(session.execute(delete(WorkerHeartbeat).where(WorkerHeartbeat.last_seen_at < cutoff)).rowcount)


@dataclass(frozen=True)
class WorkerInfo:
    """A worker process that reported recently."""

    worker_id: str
    host: str
    pid: int
    mode: str
    started_at: dt.datetime
    last_seen_s: float


@dataclass(frozen=True)
class QueueHealth:
    """Workers and jobs as the health check reports them.

    Attributes
    ----------
    workers_alive : list of WorkerInfo
        Worker processes whose heartbeat is younger than ``worker_stale_after_s``.
    workers_lost : int
        Worker processes silent for longer (died without stopping; pruned after a day).
    queued : int
        Jobs waiting for a worker.
    oldest_queued_age_s : float or None
        Age of the oldest queued job, s (None: none queued).
    running : int
        Jobs running.
    stuck : int
        Running jobs whose job heartbeat is older than ``stuck_after_s``.
    stuck_after_s : float
        The threshold used.
    """

    workers_alive: list[WorkerInfo]
    workers_lost: int
    queued: int
    oldest_queued_age_s: float | None
    running: int
    stuck: int
    stuck_after_s: float

    @property
    def jobs_waiting(self) -> bool:
        """Jobs are queued or running."""
        return self.queued > 0 or self.running > 0

    @property
    def problems(self) -> list[str]:
        """What makes the service degraded (empty: nothing)."""
        out = []
        if self.jobs_waiting and not self.workers_alive:
            out.append("no worker alive while jobs wait")
        if self.stuck:
            out.append(f"{self.stuck} running job(s) without progress for {self.stuck_after_s:g} s")
        return out


def queue_health(session: Session, *, stale_after_s: float, stuck_after_s: float,
                 now: dt.datetime | None = None) -> QueueHealth:
    """Workers alive and the state of the queue (one read transaction, four small queries).

    Parameters
    ----------
    session : Session
    stale_after_s : float
        A worker heartbeat older than this (s) is a dead worker (``worker_stale_after_s``).
    stuck_after_s : float
        A running job without a job heartbeat for this long (s) is stuck.
    now : datetime, optional
    """
    if stale_after_s <= 0 or stuck_after_s <= 0:
        raise ValueError(f"stale_after_s and stuck_after_s must be > 0 s, got {stale_after_s}, {stuck_after_s}")
    now = now or utcnow()
    alive_cutoff = now - dt.timedelta(seconds=stale_after_s)
    workers, lost = [], 0
    for hb in session.scalars(select(WorkerHeartbeat).order_by(WorkerHeartbeat.started_at)):
        if hb.last_seen_at >= alive_cutoff:
            workers.append(WorkerInfo(hb.worker_id, hb.host, hb.pid, hb.mode, hb.started_at,
                                      round((now - hb.last_seen_at).total_seconds(), 3)))
        else:
            lost += 1
    queued, oldest = session.execute(
        select(func.count(), func.min(Job.created_at)).where(Job.status == JobStatus.QUEUED)).one()
    stuck_cutoff = now - dt.timedelta(seconds=stuck_after_s)
    running, stuck = session.execute(
        select(func.count(), func.count().filter(func.coalesce(Job.heartbeat_at, Job.started_at) < stuck_cutoff))
        .where(Job.status == JobStatus.RUNNING)).one()
    oldest_age = None
    if oldest is not None:
        if oldest.tzinfo is None:  # aggregate results bypass the column type on SQLite
            oldest = oldest.replace(tzinfo=dt.UTC)
        oldest_age = round(max((now - oldest).total_seconds(), 0.0), 3)
    return QueueHealth(workers, lost, int(queued), oldest_age, int(running), int(stuck or 0), float(stuck_after_s))
