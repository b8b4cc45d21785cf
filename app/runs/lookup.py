"""A run and the job whose results it shows, or the error a request gets without them."""

from __future__ import annotations

from sqlalchemy.orm import Session

from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.db import crud, results_reader
from app.db.models import Job, Run

__all__ = ["run_or_404", "run_with_results"]


def run_or_404(session: Session, run_id: int) -> Run:
    """The run; 404 naming ``run_id`` without it."""
    run = crud.get_run(session, run_id)
    if run is None:
        raise not_found("run", run_id)
    return run


def run_with_results(session: Session, run_id: int) -> tuple[Run, Job]:
    """The run and the job whose results are stored; 404 without the run, 409 without results."""
    run = run_or_404(session, run_id)
    job = results_reader.results_job(session, run_id)
    if job is None:
        latest = crud.latest_job(session, run_id)
        state = f"latest job {latest.id} is {latest.status}" if latest else "no job"
        raise ApiError(409, "profile", _("run {run_id} has no results yet ({state})", run_id=run_id, state=state))
    return run, job
