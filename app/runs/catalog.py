"""The runs as the API lists and shows them, each with its latest job and that job's progress,
and a run deleted (its rows, its files, the audit entry)."""

from __future__ import annotations

import datetime as dt
import logging
from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy.orm import Session

from app.audit import record
from app.core.errors import not_found
from app.core.runstore import RunStore
from app.core.security import Actor
from app.db import crud
from app.db.models import ChunkStatus, Job, Run
from app.db.session import Database

__all__ = ["JobView", "RunView", "job_views", "run_view", "run_page", "delete_run"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class JobView:
    """A job (detached row) and how many of its chunks are done."""

    job: Job
    chunks_done: int = 0


@dataclass(frozen=True)
class RunView:
    """A run (detached row) and its latest job, if any."""

    run: Run
    latest: JobView | None


def job_views(session: Session, jobs: Sequence[Job]) -> list[JobView]:
    """The jobs with their done chunks (one query)."""
    counts = crud.chunk_counts(session, [j.id for j in jobs])
    return [JobView(j, int(counts.get(j.id, {}).get(ChunkStatus.DONE, 0))) for j in jobs]


def _views(session: Session, runs: Sequence[Run]) -> list[RunView]:
    latest = crud.latest_jobs(session, [r.id for r in runs])
    jobs = {v.job.run_id: v for v in job_views(session, list(latest.values()))}
    return [RunView(r, jobs.get(r.id)) for r in runs]


def run_view(db: Database, run_id: int) -> RunView:
    """A run with its latest job; 404 naming ``run_id``."""
    with db.read() as session:
        run = crud.get_run(session, run_id)
        if run is None:
            raise not_found("run", run_id)
        return _views(session, [run])[0]


def run_page(db: Database, *, line_id: str | None = None, vehicle_id: str | None = None, track: str | None = None,
             start_from: dt.datetime | None = None, start_to: dt.datetime | None = None, limit: int = 50,
             offset: int = 0) -> tuple[list[RunView], int]:
    """Runs of the filters, newest start time first, with their latest jobs, and how many match."""
    with db.read() as session:
        runs, total = crud.list_runs(session, line_id=line_id, vehicle_id=vehicle_id, track=track,
                                     start_from=start_from, start_to=start_to, limit=limit, offset=offset)
        return _views(session, runs), total


def delete_run(db: Database, store: RunStore, actor: Actor, run_id: int) -> None:
    """Delete a run's rows (jobs, chunks, results, condition rows) and then its files (audited
    ``run.delete``); a worker processing the run notices that its job is gone and stops.

    Raises
    ------
    ApiError
        404 naming ``run_id``.
    """
    with db.write() as session:
        run = crud.get_run(session, run_id)
        detail = {"sha256": run.sha256, "original_filename": run.original_filename} if run else None
        deleted = crud.delete_run(session, run_id)
        if deleted:
            record(session, actor, "run.delete", target=run_id, detail=detail)
    if not deleted:
        raise not_found("run", run_id)
    store.remove_run(run_id)
    log.info("run %s deleted", run_id)
