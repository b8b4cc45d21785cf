"""Retention of the 25 cm profile rows (segment condition rows are kept for ever).

:func:`sweep_profiles` removes the profile rows of runs measured before a
cutoff (``TRACKVKF_PROFILE_RETENTION_DAYS``) and marks them
(``runs.profiles_swept_at``: their profile endpoints answer 410 Gone). On
PostgreSQL whole job-range partitions whose jobs all belong to such runs are
dropped first (:mod:`app.db.partitions`: a catalogue change, no matter how
many rows), the rest is deleted run by run, each in its own short transaction.
Runs with a queued or running job are left for the next sweep. Run it from the
command line (``trackvkf sweep-profiles``) or let the workers do it
(:mod:`worker.housekeeping`).
"""

from __future__ import annotations

import datetime as dt
import time
from dataclasses import dataclass

from sqlalchemy import and_, delete, exists, func, or_, select, update

from app.db.models import Job, JobStatus, ProfileBin, Run, utcnow
from app.db.partitions import PREFIX, drop_partition, list_partitions
from app.db.session import Database

__all__ = ["SweepResult", "sweep_profiles"]


@dataclass(frozen=True)
class SweepResult:
    """What a sweep did.

    Attributes
    ----------
    runs : int
        Runs whose 25 cm rows are gone now (marked swept).
    rows : int
        Rows deleted one by one (not counting dropped partitions).
    partitions : list of str
        Partitions dropped (PostgreSQL).
    seconds : float
        Wall time, s.
    """

    runs: int
    rows: int
    partitions: list[str]
    seconds: float


def _old(cutoff: dt.datetime):
    """Runs measured before the cutoff (start time, else upload time)."""
    return func.coalesce(Run.start_time, Run.created_at) < cutoff


def sweep_profiles(db: Database, cutoff: dt.datetime, *, dry_run: bool = False) -> SweepResult:
    """Remove the 25 cm rows of runs measured before ``cutoff`` (see the module docstring).

    Parameters
    ----------
    cutoff : datetime
        Aware datetime; runs measured before it lose their profile rows.
    dry_run : bool
        Count the runs only; change nothing.
    """
    if cutoff.tzinfo is None:
        raise ValueError("cutoff: give a timezone")
    t0 = time.perf_counter()
    active = exists().where(Job.run_id == Run.id, Job.status.in_(JobStatus.ACTIVE))
    with db.read() as session:
        run_ids = list(session.scalars(select(Run.id).where(_old(cutoff), Run.profiles_swept_at.is_(None), ~active)
                                       .order_by(Run.id)))
    if dry_run:
        return SweepResult(len(run_ids), 0, [], time.perf_counter() - t0)
    dropped: list[str] = []
    with db.read() as session:
        parts = [p for p in list_partitions(session)
                 if not p.is_default and p.hi is not None and (p.name.startswith(PREFIX) or p.lo is None)]
    for p in parts:
        lo = p.lo if p.lo is not None else -(2**31)
        with db.write() as session:
            keep = session.scalar(select(func.count()).select_from(Job).join(Run, Run.id == Job.run_id).where(
                Job.id >= lo, Job.id < p.hi,
                or_(~_old(cutoff), Job.status.in_(JobStatus.ACTIVE)),
            ))
            newer = session.scalar(select(func.max(Job.id)))
            if keep or newer is None or newer < p.hi:  # rows of recent runs, or the newest range: keep
                continue
            drop_partition(session, p.name)
            dropped.append(p.name)
    rows = 0
    for run_id in run_ids:
        with db.write() as session:
            if session.scalar(select(Run.id).where(Run.id == run_id).with_for_update()) is None:
                continue  # deleted meanwhile
            if session.scalar(select(Job.id).where(Job.run_id == run_id, Job.status.in_(JobStatus.ACTIVE))):
                continue  # reprocessing started meanwhile
            jobs = select(Job.id).where(Job.run_id == run_id).scalar_subquery()
            rows += session.execute(delete(ProfileBin).where(ProfileBin.job_id.in_(jobs))).rowcount or 0
            session.execute(update(Run).where(and_(Run.id == run_id)).values(profiles_swept_at=utcnow()))
    return SweepResult(len(run_ids), rows, dropped, time.perf_counter() - t0)
