"""Processing jobs: list, detail, cancel, reprocess with other settings."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Depends, Query, Request, status

from app.api.deps import (
    DbDep,
    EngineerActor,
    JobId,
    PageOffset,
    RunId,
    SettingsDep,
    StoreDep,
    check_page_size,
    require_role,
)
from app.api.language import request_language
from app.api.schemas.from_rows import job_out
from app.api.schemas.jobs import JobList, JobOut, ProcessingSettingsIn
from app.core.ids import MAX_ID
from app.runs import jobs
from app.runs.catalog import JobView

__all__ = ["router"]

router = APIRouter(tags=["jobs"])

def _job_list(views: list, total: int, limit: int, offset: int, lang: str) -> JobList:
    return JobList(items=[job_out(v, lang) for v in views], total=total, limit=limit, offset=offset)


@router.get("/runs/{run_id}/jobs", response_model=JobList, summary="Jobs of a run")
def run_jobs(
    run_id: RunId,
    db: DbDep,
    settings: SettingsDep,
    request: Request,
    limit: Annotated[int, Query(ge=1)] = 50,
    offset: PageOffset = 0,
) -> JobList:
    """The processing jobs of a run, newest first."""
    check_page_size(limit, settings)
    views, total = jobs.job_page(db, run_id=run_id, limit=limit, offset=offset, run_must_exist=True)
    return _job_list(views, total, limit, offset, request_language(request).code)


@router.post(
    "/runs/{run_id}/jobs",
    response_model=JobOut,
    status_code=status.HTTP_201_CREATED,
    summary="Reprocess a run with other settings (engineer)",
    dependencies=[Depends(require_role("engineer"))],
    responses={409: {"description": "The run already has a queued or running job"}},
)
def reprocess(
    run_id: RunId,
    db: DbDep,
    actor: EngineerActor,
    body: Annotated[ProcessingSettingsIn | None, Body()] = None,
) -> JobOut:
    """Queue a new processing job for a run.

    Settings not given keep the values of the run's latest job. When the job
    is done its results replace the run's stored profiles and wheels.
    """
    changes = body.model_dump(exclude_none=True) if body is not None else {}
    return job_out(JobView(jobs.reprocess(db, run_id, changes, actor)))


@router.get("/jobs", response_model=JobList, summary="List jobs")
def list_jobs(
    db: DbDep,
    settings: SettingsDep,
    request: Request,
    status_: Annotated[
        str | None,
        Query(alias="status", description="queued, running, done, failed or cancelled", max_length=16),
    ] = None,
    run_id: Annotated[int | None, Query(ge=1, le=MAX_ID)] = None,
    limit: Annotated[int, Query(ge=1)] = 50,
    offset: PageOffset = 0,
) -> JobList:
    """All jobs, newest first, optionally by status and run."""
    check_page_size(limit, settings)
    views, total = jobs.job_page(db, run_id=run_id, status=status_, limit=limit, offset=offset)
    return _job_list(views, total, limit, offset, request_language(request).code)


@router.get("/jobs/{job_id}", response_model=JobOut, summary="Job detail")
def get_job(job_id: JobId, db: DbDep, request: Request) -> JobOut:
    """Status, progress, error, timings, settings and provenance of a job."""
    return job_out(jobs.job_view(db, job_id), request_language(request).code)


@router.post(
    "/jobs/{job_id}/cancel",
    response_model=JobOut,
    summary="Cancel a job (engineer)",
    dependencies=[Depends(require_role("engineer"))],
    responses={409: {"description": "The job is already done, failed or cancelled"}},
)
def cancel_job(
    job_id: JobId, db: DbDep, store: StoreDep, actor: EngineerActor
) -> JobOut:
    """Cancel a queued job at once, a running one at its next chunk boundary.

    The response shows ``cancel_requested`` true; the job's status becomes
    ``cancelled`` when the worker has stopped. A queued job's chunk files (of
    an attempt interrupted by a worker's shutdown) are removed at once; a
    running job's by its worker.
    """
    return job_out(jobs.cancel(db, store, job_id, actor))
