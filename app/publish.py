"""The publish step: a finished job's results become its run's, in one transaction.

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
4. the run's places are found and its line's places advanced, with the alerts of new places and
   tier changes (:func:`app.places.update.update_places`, in a savepoint: a failure there is
   reported in the job's metadata and publishes the rest);
5. the job is marked done with its provenance (:func:`app.db.queue.mark_done`).

Readers switch from the run's old results to the new ones at the commit, and an
alert exists exactly when its flags do.
"""

from __future__ import annotations

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
from app.places.config import DEFAULT_PLACES_CONFIG, PlacesConfig
from app.places.update import update_places

__all__ = ["publish_job", "store_wheel_rows"]


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
) -> bool:
    """Store (unless already stored) and publish a job's results and mark it done, in one transaction.

    Nothing is written if the job is no longer owned by this worker, a cancel
    was requested meanwhile, or the run was deleted.

    Parameters
    ----------
    profiles : pandas.DataFrame or None
        The job's profile rows, or None when they were stored wheel by wheel
        already (:func:`store_wheel_rows`, fan-out mode).
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

    Returns
    -------
    bool
        True if the results were published.
    """
    if profiles is not None:
        partitions.ensure_for_job(db, job_id)  # PostgreSQL: before the rows, in its own transaction
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
        stored = store_run_condition(session, run_id, job_id, config=condition, profiles=profiles)
        deliveries = enqueue_new_flags(session, run_id, stored.line, stored.flags) if stored.stored else []
        summary = stored.summary(len(deliveries))
        if stored.stored:
            summary["places"] = update_places(session, run_id, stored.line, job_id, config=places).summary()
        queue.mark_done(session, job_id, {**meta, "condition": summary})
        return True


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
