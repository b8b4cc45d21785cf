"""The places follow-up of the publish step (issue 24): a published run's places, after the publish commit.

The publish transaction (:func:`app.publish.publish_job`) commits the run's results, condition rows,
flags and their alerts with the job marked done, and writes a durable marker of the run in the same
commit (:func:`mark_pending`, a ``places_pending`` row). The run's places update
(:func:`app.places.update.update_places`) follows in transactions of its own
(:func:`complete_run`):

1. **read** (no write lock; on SQLite a deferred read transaction, never blocking a writer): the
   store's 10 m rows of the run and its history read, the curves fitted, the run's places found
   (:func:`app.places.update.prepare_run`) — the long part (seconds for a 50 km line);
2. **write** (short: SQLite's write lock is held only here): the marker claimed (PostgreSQL:
   ``FOR UPDATE``; a second worker on the same run waits and then finds it gone), the run checked
   to be its line's oldest pending run, its inputs checked unchanged since the read (the run's
   condition rows, its history runs and theirs: otherwise the read is done again), the line's
   places advanced and written with their alerts (:func:`~app.places.update.apply_prepared`), the
   job's ``meta["condition"]["places"]`` set to what they did, the marker deleted — one commit.

So a run is applied **exactly once** (the marker goes in the commit that applies it, and an applied
run is never applied again: ``place_runs``), **in the order of its line's runs** (the oldest pending
run of a line first; a later run waits for it, as the places are a history), and **never lost**: a
worker killed between the publish commit and the follow-up's commit leaves the marker, and the
worker's ``places-followup`` loop (:mod:`worker.background`, both worker modes; its first round at
the worker's start is the start-up sweep; it leaves runs marked less than ``places_followup_grace_s``
ago to the worker that published them) completes it. A failing update is logged, reported in the
job's metadata (``meta["condition"]["places"]``: ``applied`` false, ``reason``, ``attempts``,
``retry_at``) and on ``/metrics`` (``trackvkf_places_pending{state}``), and retried with exponential
back-off (``places_retry_base_s`` doubling up to ``places_retry_max_s``); after
``places_max_attempts`` the marker is kept as given up (``gave_up``), and the line's later runs go on.

Between the publish commit and the follow-up's commit readers see the run's new results and
condition rows with the line's places as of its previous run: the places lag the run by the
follow-up (:func:`line_places_status` says how far: ``places_pending``, ``places_updated_at``).
"""

from __future__ import annotations

import datetime as dt
import logging
import time
from dataclasses import dataclass
from typing import Any

from sqlalchemy import and_, delete, func, insert, or_, select
from sqlalchemy.orm import Session

from app.core.jsonable import iso_time
from app.db import places as q
from app.db.models import ConditionLine, ConditionRun, Job, PlaceRun, PlacesPending, utcnow
from app.db.session import Database
from app.places.config import DEFAULT_PLACES_CONFIG, FollowupPolicy, PlacesConfig
from app.places.index import method_version
from app.places.update import (
    PlacesUpdate,
    PreparedRun,
    history_of,
    line_actions,
    prepare_run,
    update_places,
)

__all__ = ["PENDING_SUMMARY", "FollowupPolicy", "DEFAULT_FOLLOWUP", "FollowupResult", "mark_pending", "due_runs",
           "complete_run", "run_pending", "line_places_status",
           "apply_stored_runs"]

log = logging.getLogger(__name__)

#: ``meta["condition"]["places"]`` of a job between its publish commit and its places follow-up
PENDING_SUMMARY: dict[str, Any] = {"pending": True}
#: longest error text kept with a failing places update, characters
_MAX_ERROR_CHARS = 2000
#: reads done again when the run's inputs changed meanwhile, before the read is done under the write lock
_MAX_REREADS = 2


DEFAULT_FOLLOWUP = FollowupPolicy()


@dataclass(frozen=True)
class FollowupResult:
    """What one follow-up of a run did.

    Attributes
    ----------
    run_id : int
    outcome : str
        ``applied`` (the places advanced), ``not_applied`` (nothing to do for the places: the summary
        says why), ``failed`` (retried later), ``gave_up``, ``waiting`` (an earlier run of its line is
        pending), ``done_already`` (no marker: another worker did it).
    summary : dict or None
        The job's ``meta["condition"]["places"]`` now.
    read_s, write_s : float
        Wall time of the read (no write lock) and of the write transaction, s.
    """

    run_id: int
    outcome: str
    summary: dict[str, Any] | None = None
    read_s: float = 0.0
    write_s: float = 0.0


def mark_pending(session: Session, run_id: int, line_key: int, job_id: int) -> None:
    """Record in the publish transaction that run ``run_id``'s places are to be updated (a reprocessed run's
    marker is replaced: attempts, error, given up reset).

    Delete, then insert: a follow-up of the run committing meanwhile (PostgreSQL) only makes the delete
    find nothing.
    """
    when = session.scalar(select(ConditionRun.run_time).where(ConditionRun.run_id == run_id))
    if when is None:
        raise ValueError(f"run {run_id} has no condition rows: no places to update")
    session.execute(delete(PlacesPending).where(PlacesPending.run_id == run_id))
    session.execute(insert(PlacesPending).values(run_id=run_id, line_key=line_key, job_id=job_id, run_time=when,
                                                 queued_at=utcnow(), attempts=0, gave_up=False))


def _earlier(row: PlacesPending):
    """Condition: a pending run of ``row``'s line before it (its places first)."""
    return and_(PlacesPending.line_key == row.line_key, PlacesPending.gave_up.is_(False),
                or_(PlacesPending.run_time < row.run_time,
                    and_(PlacesPending.run_time == row.run_time, PlacesPending.run_id < row.run_id)))


def due_runs(session: Session, now: dt.datetime | None = None, *, line_key: int | None = None,
             min_age_s: float = 0.0) -> list[int]:
    """The runs whose places update is due: of each line (or of ``line_key``) its oldest pending run not
    given up, unless it waits for its back-off (then the line's later runs wait too) or was marked less
    than ``min_age_s`` ago."""
    now = now or utcnow()
    fresh = now - dt.timedelta(seconds=min_age_s)
    stmt = select(PlacesPending).where(PlacesPending.gave_up.is_(False))
    if line_key is not None:
        stmt = stmt.where(PlacesPending.line_key == line_key)
    rows = session.scalars(stmt.order_by(PlacesPending.line_key, PlacesPending.run_time, PlacesPending.run_id))
    out, seen = [], set()
    for row in rows:
        if row.line_key in seen:
            continue
        seen.add(row.line_key)
        if (row.next_attempt_at is None or row.next_attempt_at <= now) and (min_age_s <= 0 or row.queued_at <= fresh):
            out.append(int(row.run_id))
    return out


def _inputs(session: Session, run_id: int, line: ConditionLine, version: str, config: PlacesConfig) -> tuple:
    """What a run's places are found from, in short: its condition rows' job and publication, its history runs
    and their publications (a run reprocessed or deleted meanwhile changes it), and the line's maintenance
    actions (a grinding recorded meanwhile changes which changes its places take as the rail's)."""
    cr = session.get(ConditionRun, run_id)
    if cr is None:
        return (None,)
    history = history_of(session, run_id, line, version, config=config)
    ids = [r for r, _ in history]
    published = session.scalar(select(func.max(ConditionRun.published_at)).where(ConditionRun.run_id.in_(ids))) \
        if ids else None
    n = session.scalar(select(func.count()).select_from(ConditionRun).where(ConditionRun.run_id.in_(ids))) \
        if ids else 0
    actions = tuple((a.id, a.start_m, a.end_m, a.day, a.kind) for a in line_actions(session, line)[0])
    return cr.job_id, cr.published_at, cr.run_time, tuple(ids), published, n, actions


def _set_summary(session: Session, job_id: int, summary: dict[str, Any]) -> None:
    job = session.get(Job, job_id)
    if job is None:
        return
    meta = dict(job.meta or {})
    meta["condition"] = {**(meta.get("condition") or {}), "places": summary}
    job.meta = meta


def _claim(session: Session, run_id: int) -> PlacesPending | None:
    stmt = select(PlacesPending).where(PlacesPending.run_id == run_id)
    if session.get_bind().dialect.name == "postgresql":
        stmt = stmt.with_for_update()
    return session.scalar(stmt.execution_options(populate_existing=True))


def _read(db: Database, run_id: int, config: PlacesConfig) -> tuple[Any, tuple | None] | None:
    """Phase 1 (no write lock): the run's places found; None: no marker (done already or given up)."""
    with db.read() as s:
        row = s.get(PlacesPending, run_id)
        if row is None or row.gave_up:
            return None
        cr = s.get(ConditionRun, run_id)
        line = s.get(ConditionLine, row.line_key)
        if cr is None or line is None:
            return PlacesUpdate(False, "the run has no condition rows"), None
        job = s.get(Job, cr.job_id)
        version = method_version(job.settings if job is not None else None)
        prep = prepare_run(s, run_id, line, version, config=config)
        return prep, (_inputs(s, run_id, line, version, config) if isinstance(prep, PreparedRun) else None)


def complete_run(db: Database, run_id: int, *, config: PlacesConfig = DEFAULT_PLACES_CONFIG,
                 policy: FollowupPolicy = DEFAULT_FOLLOWUP) -> FollowupResult:
    """The places follow-up of one published run (module docstring): read, then one short write transaction.

    Never raises for a failure of the places update: it is logged, reported in the job's metadata and the
    marker's attempts, and retried after the back-off (:func:`run_pending`, the worker's loop).
    """
    t0 = time.perf_counter()
    read_s = 0.0
    try:
        for reread in range(_MAX_REREADS + 1):
            t_read = time.perf_counter()
            got = _read(db, run_id, config) if reread < _MAX_REREADS else (None, None)
            if got is None:
                return FollowupResult(run_id, "done_already")
            prep, inputs = got
            read_s += time.perf_counter() - t_read
            t_write = time.perf_counter()
            with db.write() as s:
                row = _claim(s, run_id)
                if row is None or row.gave_up:
                    return FollowupResult(run_id, "done_already", read_s=read_s)
                if s.scalar(select(PlacesPending.run_id).where(_earlier(row)).limit(1)) is not None:
                    return FollowupResult(run_id, "waiting", read_s=read_s)
                line = s.get(ConditionLine, row.line_key)
                q.lock_places(s)
                use = prep if isinstance(prep, PreparedRun) else None
                if line is None or s.get(ConditionRun, run_id) is None:
                    out = PlacesUpdate(False, "the run has no condition rows")
                elif use is not None and _inputs(s, run_id, line, use.version, config) != inputs:
                    continue  # a run of the history or the run itself changed meanwhile: read again
                else:  # use None (not applicable when read, or the last try): the whole update under the lock
                    out = update_places(s, run_id, line, row.job_id, config=config, prepared=use,
                                        raise_errors=True)
                summary = out.summary()
                _set_summary(s, row.job_id, summary)
                s.delete(row)
            write_s = time.perf_counter() - t_write
            log.info("places of run %s %s (read %.2f s, write %.2f s)", run_id,
                     "updated" if out.applied else f"not updated: {out.reason}", read_s, write_s)
            return FollowupResult(run_id, "applied" if out.applied else "not_applied", summary, read_s, write_s)
        raise AssertionError("unreachable")  # pragma: no cover - the last try does not continue
    except Exception as exc:  # noqa: BLE001 - recorded and retried, never lost
        log.exception("places of run %s not updated (follow-up failed after %.2f s)", run_id,
                      time.perf_counter() - t0)
        return _record_failure(db, run_id, exc, policy)


def _record_failure(db: Database, run_id: int, exc: BaseException, policy: FollowupPolicy) -> FollowupResult:
    error = f"{type(exc).__name__}: {exc}"[:_MAX_ERROR_CHARS]
    try:
        with db.write() as s:
            row = s.get(PlacesPending, run_id)
            if row is None:
                return FollowupResult(run_id, "done_already")
            row.attempts = int(row.attempts or 0) + 1
            row.last_error = error
            row.gave_up = row.attempts >= policy.max_attempts
            row.next_attempt_at = None if row.gave_up else utcnow() + dt.timedelta(seconds=policy.backoff_s(row.attempts))
            summary = {"applied": False, "reason": f"error: {error}", "pending": not row.gave_up,
                       "attempts": row.attempts,
                       "retry_at": row.next_attempt_at.isoformat() if row.next_attempt_at is not None else None}
            _set_summary(s, row.job_id, summary)
            gave_up = row.gave_up
    except Exception:  # noqa: BLE001 - the marker stays: the next round retries
        log.exception("cannot record the failed places update of run %s", run_id)
        return FollowupResult(run_id, "failed")
    if gave_up:
        log.error("places of run %s: given up after %d attempts (%s); the line's later runs go on",
                  run_id, summary["attempts"], error)
    else:
        log.warning("places of run %s: attempt %d failed (%s), retry at %s", run_id, summary["attempts"], error,
                    summary["retry_at"])
    return FollowupResult(run_id, "gave_up" if gave_up else "failed", summary)


def run_pending(db: Database, *, config: PlacesConfig = DEFAULT_PLACES_CONFIG,
                policy: FollowupPolicy = DEFAULT_FOLLOWUP, line_key: int | None = None,
                max_runs: int | None = None, min_age_s: float = 0.0) -> list[FollowupResult]:
    """Complete every due places update (of one line, or of all), each line's runs in order.

    The publish step calls it for its line after its commit; the worker's ``places-followup`` loop for all
    lines (at its start: the runs a killed worker left; then the retries), with ``min_age_s`` =
    ``policy.grace_s`` (runs just published are their publisher's).

    Returns
    -------
    list of FollowupResult
        One per run handled (empty: nothing due).
    """
    out: list[FollowupResult] = []
    tried: set[int] = set()
    while max_runs is None or len(out) < max_runs:
        with db.read() as s:
            due = [r for r in due_runs(s, line_key=line_key, min_age_s=min_age_s) if r not in tried]
        if not due:
            break
        for run_id in due:
            tried.add(run_id)
            out.append(complete_run(db, run_id, config=config, policy=policy))
            if max_runs is not None and len(out) >= max_runs:
                break
    return out


def line_places_status(session: Session, line_key: int) -> dict[str, Any]:
    """How current a line's places are, for the readers: ``places_pending`` (published runs whose places update
    is still to come, given-up ones included), ``places_failed`` (of them, failing or given up),
    ``places_run_id`` and ``places_updated_at`` (the newest run applied and when)."""
    pending = session.execute(select(func.count(), func.count(PlacesPending.last_error))
                              .where(PlacesPending.line_key == line_key)).one()
    last = session.execute(select(PlaceRun.run_id, PlaceRun.applied_at).where(PlaceRun.line_key == line_key)
                           .order_by(PlaceRun.applied_at.desc(), PlaceRun.run_id.desc()).limit(1)).first()
    return {"places_pending": int(pending[0]), "places_failed": int(pending[1]),
            "places_run_id": int(last[0]) if last is not None else None,
            "places_updated_at": iso_time(last[1]) if last is not None else None}


def apply_stored_runs(db: Any, line_id: str, track: str, *, config: PlacesConfig = DEFAULT_PLACES_CONFIG,
                      alerts: bool = False) -> list[PlacesUpdate]:
    """Apply every run of a line in the condition store that its places have not seen, oldest first, one
    transaction each (runs published before the places existed, a generated fleet history). Alerts are
    off by default: a history replayed at once is not news."""
    out = []
    with db.read() as session:
        line = session.scalar(select(ConditionLine).where(ConditionLine.line_id == line_id,
                                                          ConditionLine.track == track))
        if line is None:
            return out
        runs = session.execute(select(ConditionRun.run_id, ConditionRun.job_id).where(
            ConditionRun.line_key == line.id).order_by(ConditionRun.run_time, ConditionRun.run_id)).all()
        done = set(session.scalars(select(PlaceRun.run_id).where(PlaceRun.line_key == line.id)))
        pending = set(session.scalars(select(PlacesPending.run_id).where(PlacesPending.line_key == line.id)))
    for run_id, job_id in runs:
        if run_id in done:
            continue
        if run_id in pending:  # published with its places to come: its follow-up (marker, job summary, alerts)
            r = complete_run(db, int(run_id), config=config)
            out.append(PlacesUpdate(r.outcome == "applied", None if r.outcome == "applied" else r.outcome))
            continue
        with db.write() as session:
            ln = session.get(ConditionLine, line.id)
            out.append(update_places(session, int(run_id), ln, int(job_id), config=config, alerts=alerts))
    return out
