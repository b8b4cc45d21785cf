"""Processing jobs: list, detail, cancel, reprocess with other settings."""

from __future__ import annotations

import dataclasses
from typing import Annotated

from fastapi import APIRouter, Body, Depends, Query, Request, status

from app.analysis.settings import ProcessingSettings
from app.api.audit import record
from app.api.deps import (
    DbDep,
    EngineerDep,
    JobId,
    PageOffset,
    RunId,
    SettingsDep,
    StoreDep,
    check_page_size,
    require_role,
)
from app.api.errors import ApiError, not_found
from app.api.schemas.jobs import JobList, JobOut, ProcessingSettingsIn
from app.api.views import job_out
from app.db import crud
from app.db.models import N_ORDER_COLUMNS, JobStatus
from app.db.session import Database

__all__ = ["router", "settings_from_request"]

router = APIRouter(tags=["jobs"])

_SETTING_FIELDS = tuple(f.name for f in dataclasses.fields(ProcessingSettings))


def settings_from_request(base: dict | None, changes: dict) -> ProcessingSettings:
    """Merge ``changes`` onto ``base`` settings and validate them.

    Raises
    ------
    ApiError
        422 naming the offending setting.
    """
    merged = {k: v for k, v in (base or {}).items() if k in _SETTING_FIELDS}
    if base is not None:  # stored settings lacking newer keys mean what they meant then
        try:
            merged = ProcessingSettings.from_stored(merged).to_dict()
        except (ValueError, TypeError):
            pass  # validated with the changes below
    merged.update(changes)
    try:
        settings = ProcessingSettings.from_dict(merged)
    except (ValueError, TypeError) as exc:
        text = str(exc)
        field = next((f for f in _SETTING_FIELDS if text.startswith(f)), "settings")
        raise ApiError(422, field, text) from None
    if settings.n_wheel_orders > N_ORDER_COLUMNS:
        raise ApiError(
            422,
            "n_wheel_orders",
            f"the service stores at most {N_ORDER_COLUMNS} wheel orders per bin, "
            f"got {settings.n_wheel_orders}",
        )
    return settings


def _job_page(
    db: Database,
    *,
    run_id: int | None = None,
    status_: str | None = None,
    limit: int = 50,
    offset: int = 0,
) -> JobList:
    with db.read() as session:
        jobs, total = crud.list_jobs(
            session, run_id=run_id, status=status_, limit=limit, offset=offset
        )
        counts = crud.chunk_counts(session, [j.id for j in jobs])
    return JobList(
        items=[job_out(j, counts.get(j.id)) for j in jobs], total=total, limit=limit, offset=offset
    )


@router.get("/runs/{run_id}/jobs", response_model=JobList, summary="Jobs of a run")
def run_jobs(
    run_id: RunId,
    db: DbDep,
    settings: SettingsDep,
    limit: Annotated[int, Query(ge=1)] = 50,
    offset: PageOffset = 0,
) -> JobList:
    """The processing jobs of a run, newest first."""
    check_page_size(limit, settings)
    with db.read() as session:
        if crud.get_run(session, run_id) is None:
            raise not_found("run", run_id)
    return _job_page(db, run_id=run_id, limit=limit, offset=offset)


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
    request: Request,
    db: DbDep,
    principal: EngineerDep,
    body: Annotated[ProcessingSettingsIn | None, Body()] = None,
) -> JobOut:
    """Queue a new processing job for a run.

    Settings not given keep the values of the run's latest job. When the job
    is done its results replace the run's stored profiles and wheels.
    """
    changes = body.model_dump(exclude_none=True) if body is not None else {}
    with db.write() as session:
        if crud.get_run(session, run_id) is None:
            raise not_found("run", run_id)
        latest = crud.latest_job(session, run_id)
        settings = settings_from_request(latest.settings if latest else None, changes)
        active = crud.active_job(session, run_id)
        if active is not None:
            raise ApiError(
                409,
                "job",
                f"run {run_id} already has job {active.id} {active.status}; cancel it first",
            )
        job = crud.create_job(session, run_id, settings.to_dict(), principal.name)
        record(session, request, principal, "job.create", target=run_id,
               detail={"job_id": job.id, "settings": changes})
    return job_out(job)


@router.get("/jobs", response_model=JobList, summary="List jobs")
def list_jobs(
    db: DbDep,
    settings: SettingsDep,
    status_: Annotated[
        str | None,
        Query(alias="status", description="queued, running, done, failed or cancelled", max_length=16),
    ] = None,
    run_id: Annotated[int | None, Query(ge=1, le=2**31 - 1)] = None,
    limit: Annotated[int, Query(ge=1)] = 50,
    offset: PageOffset = 0,
) -> JobList:
    """All jobs, newest first, optionally by status and run."""
    check_page_size(limit, settings)
    if status_ is not None and status_ not in JobStatus.ALL:
        raise ApiError(422, "status", f"must be one of {', '.join(JobStatus.ALL)}")
    return _job_page(db, run_id=run_id, status_=status_, limit=limit, offset=offset)


@router.get("/jobs/{job_id}", response_model=JobOut, summary="Job detail")
def get_job(job_id: JobId, db: DbDep) -> JobOut:
    """Status, progress, error, timings, settings and provenance of a job."""
    with db.read() as session:
        job = crud.get_job(session, job_id)
        if job is None:
            raise not_found("job", job_id)
        counts = crud.chunk_counts(session, [job_id])
        return job_out(job, counts.get(job_id))


@router.post(
    "/jobs/{job_id}/cancel",
    response_model=JobOut,
    summary="Cancel a job (engineer)",
    dependencies=[Depends(require_role("engineer"))],
    responses={409: {"description": "The job is already done, failed or cancelled"}},
)
def cancel_job(
    job_id: JobId, request: Request, db: DbDep, store: StoreDep, principal: EngineerDep
) -> JobOut:
    """Cancel a queued job at once, a running one at its next chunk boundary.

    The response shows ``cancel_requested`` true; the job's status becomes
    ``cancelled`` when the worker has stopped. A queued job's chunk files (of
    an attempt interrupted by a worker's shutdown) are removed at once; a
    running job's by its worker.
    """
    with db.write() as session:
        outcome = crud.request_cancel(session, job_id)
        if outcome is None:
            raise not_found("job", job_id)
        job = crud.get_job(session, job_id)
        assert job is not None
        if outcome == "final":
            raise ApiError(409, "job", f"job {job_id} is already {job.status}")
        record(session, request, principal, "job.cancel", target=job_id, detail={"run_id": job.run_id})
        session.refresh(job)
        counts = crud.chunk_counts(session, [job_id])
        answer = job_out(job, counts.get(job_id))
    if outcome == "cancelled":
        store.remove_job_files(answer.run_id, job_id)
    return answer
