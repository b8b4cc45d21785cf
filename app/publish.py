"""The publish step: a finished job's results become its run's, in one transaction; its places follow.

Both worker modes end a job through :func:`publish_job` (the local worker with
the job's profile rows in hand, the fan-out tasks after :func:`store_wheel_rows`
stored them wheel by wheel). In one transaction, guarded by the job's state
(:func:`app.db.queue.owned`: still running under this owner, no cancel requested,
the run not deleted):

1. the job's profile rows are stored (unless already stored) and made the run's,
   its wheel rows replace the run's and the older jobs' profile rows go
   (:mod:`app.db.results_writer`);
2. the run's segment condition rows, change tests and flags are written
   (:func:`app.condition.writer.store_run_condition`);
3. the alerts of its new flags are queued in the outbox (:mod:`app.condition.alerts`);
4. the run is marked **places pending** (:func:`app.places.followup.mark_pending`: a
   ``places_pending`` row; the job's ``meta["condition"]["places"]`` says ``{"pending": true}``);
5. the job is marked done with its provenance (:func:`app.db.queue.mark_done`).

Readers switch from the run's old results to the new ones at the commit, and an
alert exists exactly when its flags do.

Then, in transactions of its own, the **places follow-up** (issue 24,
:mod:`app.places.followup`): the run's places are found (reads only: no write
lock) and its line's places advanced, with the alerts of new places and tier
changes (:func:`app.places.update.update_places`, a short write transaction that
also deletes the marker and sets ``meta["condition"]["places"]`` to what the
places did). It runs here right after the commit for the run's line (its older
pending runs first); a worker killed before it, or a failing update (retried with
back-off), is completed by the worker's ``places-followup`` loop
(:mod:`worker.background`). Until then the line's places are those of its
previous run (``places_pending`` on ``GET /condition/places``). The places update
no longer holds the publish transaction (SQLite's write lock) for seconds.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import pandas as pd
from sqlalchemy import select, update

from app.condition.alerts import enqueue_new_flags
from app.condition.config import DEFAULT_CONDITION_CONFIG, ConditionConfig
from app.condition.writer import store_run_condition
from app.db import partitions, queue, results_writer
from app.db.models import Job, utcnow
from app.db.session import Database
from app.places import followup
from app.places.config import DEFAULT_PLACES_CONFIG, PlacesConfig

__all__ = ["publish_job", "store_wheel_rows"]

log = logging.getLogger(__name__)


def publish_job(
    db: Database,
    job_id: int,
    run_id: int,
    profiles: pd.DataFrame | None,
    wheels: Sequence[dict[str, Any]],
    meta: dict[str, Any],
    *,
    worker_id: str | None,
    condition: ConditionConfig = DEFAULT_CONDITION_CONFIG,
    places: PlacesConfig = DEFAULT_PLACES_CONFIG,
    places_followup: followup.FollowupPolicy | None = followup.DEFAULT_FOLLOWUP,
) -> bool:
    """Store (unless already stored) and publish a job's results and mark it done, in one transaction;
    then the places follow-up of its line (module docstring).

    Nothing is written if the job is no longer owned by this worker, a cancel
    was requested meanwhile, or the run was deleted.

    Parameters
    ----------
    profiles : pandas.DataFrame or None
        The job's profile rows (they replace any of its rows stored wheel by wheel: the fan-out's
        rows with its track impacts bridged), or None when the rows stored wheel by wheel
        (:func:`store_wheel_rows`, fan-out mode) are the results as they stand.
    wheels : sequence of dict
        The wheels' out-of-roundness results (``RunResults.wheels``).
    meta : dict
        The job's provenance; the condition store's summary of the run is added
        as ``meta["condition"]``.
    worker_id : str or None
        Owner of the job; None: any owner (fan-out mode).
    condition : ConditionConfig
        How the run's segment condition rows are made.
    places : PlacesConfig
        How its places are found and followed (``meta["condition"]["places"]`` says what they did).
    places_followup : FollowupPolicy or None
        Retries of the places follow-up, run after the commit for the run's line; None: not here
        (left to the worker's ``places-followup`` loop).

    Returns
    -------
    bool
        True if the results were published.
    """
    if profiles is not None:
        partitions.ensure_for_job(db, job_id)  # PostgreSQL: before the rows, in its own transaction
    line_key = _publish(db, job_id, run_id, profiles, wheels, meta, worker_id, condition)
    if line_key is False:
        return False
    if line_key is not None and places_followup is not None:
        try:  # its own transactions: the run is published whatever happens here
            followup.run_pending(db, config=places, policy=places_followup, line_key=line_key)
        except Exception:  # noqa: BLE001 - e.g. the database away: the marker stays, the worker's loop retries
            log.exception("places follow-up of run %s not run; the worker's places-followup loop will", run_id)
    return True


def _publish(db: Database, job_id: int, run_id: int, profiles: pd.DataFrame | None,
             wheels: Sequence[dict[str, Any]], meta: dict[str, Any], worker_id: str | None,
             condition: ConditionConfig) -> int | None | bool:
    """The publish transaction; the line key of a run marked places pending, None: none, False: not published."""
    with db.write() as session:
        # the run first, then the job: the order delete_run locks them in (no deadlock)
        if not results_writer.lock_run_for_results(session, run_id):
            return False
        result = session.execute(
            update(Job)
            .where(queue.owned(job_id, worker_id), Job.cancel_requested.is_(False))
            .values(heartbeat_at=utcnow())
        )
        if result.rowcount != 1:
            return False
        if profiles is not None:
            results_writer.store_profile_rows(session, run_id, job_id, profiles)
        results_writer.publish_results(session, run_id, job_id, wheels)
        stored = store_run_condition(session, run_id, job_id, config=condition, profiles=profiles,
                                     track_impacts=meta.get("track_impacts"))
        deliveries = enqueue_new_flags(session, run_id, stored.line, stored.flags) if stored.stored else []
        summary = stored.summary(len(deliveries))
        line_key = None
        if stored.stored:
            followup.mark_pending(session, run_id, stored.line.id, job_id)
            summary["places"] = dict(followup.PENDING_SUMMARY)
            line_key = stored.line.id
        queue.mark_done(session, job_id, {**meta, "condition": summary})
        return line_key


def store_wheel_rows(db: Database, job_id: int, run_id: int, profiles: pd.DataFrame) -> bool:
    """Write the profile rows of some wheels of a running fan-out job (not yet published).

    One transaction; the job's earlier rows of these wheels are replaced, so
    a retried task never duplicates rows. The job row is share-locked while
    the rows are written: a cancel or failure that marks the job final waits
    for the commit and then discards them (:func:`app.db.queue.finish_job`,
    :func:`app.db.queue.finalize_cancel_requests`), and a job already final gets none.

    Returns
    -------
    bool
        True if the rows were written (the job is running, no cancel requested).
    """
    partitions.ensure_for_job(db, job_id)  # PostgreSQL: before the rows, in its own transaction
    with db.write() as session:
        if not results_writer.lock_run_for_results(session, run_id):
            return False
        running = session.scalar(
            select(Job.id)
            .where(queue.owned(job_id, None), Job.cancel_requested.is_(False))
            .with_for_update(read=True)
        )
        if running is None:
            return False
        results_writer.store_profile_rows(session, run_id, job_id, profiles)
        return True
