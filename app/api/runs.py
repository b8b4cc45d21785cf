"""Runs: upload (streamed), list with filters, detail, delete."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request, Response, status
from starlette.concurrency import run_in_threadpool

from app.api.deps import (
    AdminActor,
    DbDep,
    EngineerActor,
    PageOffset,
    RunId,
    SettingsDep,
    StoreDep,
    check_page_size,
    parse_time_range,
    require_role,
)
from app.api.language import request_language
from app.api.schemas.from_rows import run_detail, run_out
from app.api.schemas.runs import (
    RunDetail,
    RunList,
    RunMetadataChange,
    RunMetadataOut,
    RunMetadataPatch,
)
from app.api.upload import receive_and_create_run
from app.core.config import API_PREFIX
from app.db.session import Database
from app.io.formats import FORMATS
from app.runs import catalog
from app.runs.metadata import revise_run_metadata

__all__ = ["router"]

router = APIRouter(prefix="/runs", tags=["runs"])

_UPLOAD_BODY = {
    "required": True,
    "description": (
        "Either `multipart/form-data` with the parts `file` (the run file), `metadata` "
        "(JSON object, see docs/run-format.md; optional for HDF5 files that carry it as "
        "attributes), `format` and `channel_map` (id of a stored channel map, for MDF4/TDMS "
        "recorder files); or the raw file as the body with `format`, `metadata`, `filename` "
        "and `channel_map` as query parameters."
    ),
    "content": {
        "multipart/form-data": {
            "schema": {
                "type": "object",
                "required": ["file"],
                "properties": {
                    "file": {"type": "string", "format": "binary"},
                    "metadata": {"type": "string", "description": "JSON object"},
                    "format": {"type": "string", "enum": list(FORMATS)},
                    "channel_map": {
                        "type": "string",
                        "description": "id of a stored channel map (MDF4/TDMS recorder files)",
                    },
                },
            }
        },
        "application/octet-stream": {"schema": {"type": "string", "format": "binary"}},
        "application/x-hdf5": {"schema": {"type": "string", "format": "binary"}},
        "text/csv": {"schema": {"type": "string", "format": "binary"}},
        "application/vnd.apache.parquet": {"schema": {"type": "string", "format": "binary"}},
    },
}


@router.post(
    "",
    response_model=RunDetail,
    status_code=status.HTTP_201_CREATED,
    summary="Upload a run file (streamed); queues its processing (engineer)",
    openapi_extra={"requestBody": _UPLOAD_BODY},
    dependencies=[Depends(require_role("engineer"))],
    responses={
        200: {"description": "The same file was uploaded before: the existing run"},
        413: {"description": "The upload is larger than TRACKVKF_MAX_UPLOAD_BYTES"},
        415: {"description": "The content type is not one of a run file"},
        422: {"description": "The file or its metadata is invalid; `detail` names the problem"},
        429: {"description": "Too many uploads by this key or user (TRACKVKF_UPLOAD_RATE_LIMIT)"},
    },
)
async def upload_run(
    request: Request,
    response: Response,
    settings: SettingsDep,
    db: DbDep,
    store: StoreDep,
    actor: EngineerActor,
    format: Annotated[
        str | None,
        Query(description="hdf5, csv, parquet, mdf4 or tdms (raw body uploads)", max_length=16),
    ] = None,
    metadata: Annotated[
        str | None, Query(description="Metadata JSON object (raw body uploads)", max_length=65536)
    ] = None,
    filename: Annotated[
        str | None, Query(description="Original file name (raw body uploads)", max_length=255)
    ] = None,
    channel_map: Annotated[
        str | None,
        Query(description="Id of a stored channel map (raw body uploads of MDF4/TDMS files)", max_length=12),
    ] = None,
) -> RunDetail:
    """Create a run from an uploaded file.

    The body is streamed to the run store while its sha256 is computed. The
    same file uploaded again returns the existing run with status 200. Invalid
    input is answered with 4xx whose ``detail`` names the problem, and leaves
    no run, job or file behind.
    """
    outcome = await receive_and_create_run(
        request,
        settings=settings,
        db=db,
        store=store,
        actor=actor,
        query_format=format,
        query_metadata=metadata,
        query_filename=filename,
        query_channel_map=channel_map,
    )
    if not outcome.created:
        response.status_code = status.HTTP_200_OK
    response.headers["Location"] = f"{API_PREFIX}/runs/{outcome.run_id}"
    return await run_in_threadpool(_detail, db, outcome.run_id, request_language(request).code)


def _detail(db: Database, run_id: int, lang: str) -> RunDetail:
    return run_detail(catalog.run_view(db, run_id), lang)


@router.get("", response_model=RunList, summary="List runs")
def list_runs(
    db: DbDep,
    settings: SettingsDep,
    request: Request,
    line_id: Annotated[str | None, Query(max_length=200, description="Line id")] = None,
    vehicle_id: Annotated[str | None, Query(max_length=200, description="Vehicle id")] = None,
    track: Annotated[str | None, Query(max_length=100, description="Track id")] = None,
    date_from: Annotated[
        str | None, Query(max_length=40, description="Runs starting at/after (ISO date or datetime)")
    ] = None,
    date_to: Annotated[
        str | None, Query(max_length=40, description="Runs starting at/before (ISO date or datetime; a date includes the whole day)")
    ] = None,
    limit: Annotated[int, Query(ge=1, description="Page size")] = 50,
    offset: PageOffset = 0,
) -> RunList:
    """Runs, newest start time first, filtered by line, vehicle, track and start date."""
    check_page_size(limit, settings)
    start_from, start_to = parse_time_range(date_from, date_to, ("date_from", "date_to"), whole_days=True)
    views, total = catalog.run_page(db, line_id=line_id, vehicle_id=vehicle_id, track=track,
                                    start_from=start_from, start_to=start_to, limit=limit, offset=offset)
    lang = request_language(request).code
    return RunList(items=[run_out(v, lang) for v in views], total=total, limit=limit, offset=offset)


@router.get("/{run_id}", response_model=RunDetail, summary="Run detail")
def get_run(run_id: RunId, db: DbDep, request: Request) -> RunDetail:
    """Metadata, sha256, file summary and latest job of a run (its ingest warnings in the reader's language)."""
    return _detail(db, run_id, request_language(request).code)


@router.patch(
    "/{run_id}",
    response_model=RunMetadataOut,
    summary="Correct a run's metadata: re-ingest, reprocess, audit (engineer)",
    dependencies=[Depends(require_role("engineer"))],
    responses={
        409: {"description": "A job of the run is queued or running"},
        422: {"description": "Invalid metadata; `detail` names the field"},
    },
)
async def patch_run_metadata(
    run_id: RunId, body: RunMetadataPatch, db: DbDep, store: StoreDep, actor: EngineerActor, request: Request,
) -> RunMetadataOut:
    """Change metadata fields of a run (e.g. the line, km or start time of a re-uploaded file).

    The run's file is re-ingested with the corrected fields, the run is updated, a
    reprocessing job with the run's latest settings is queued and the change is audited
    (``run.metadata`` with each field's old and new value). Fields equal to the stored ones
    change nothing (no job). The previous results stay until the new job is done.
    """
    outcome = await run_in_threadpool(
        revise_run_metadata, db, store, run_id, body.metadata, actor
    )
    detail = await run_in_threadpool(_detail, db, run_id, request_language(request).code)
    return RunMetadataOut(
        **detail.model_dump(),
        changed=[RunMetadataChange(field=k, old=old, new=new) for k, (old, new) in outcome.changed.items()],
        reprocess_job_id=outcome.job_id,
    )


@router.delete(
    "/{run_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Delete a run with its jobs, results and files (admin)",
    dependencies=[Depends(require_role("admin"))],
)
async def delete_run(run_id: RunId, db: DbDep, store: StoreDep, actor: AdminActor) -> Response:
    """Delete the run's rows (jobs, chunks, profiles, wheels) and its files.

    A worker processing the run notices that its job is gone and stops.
    """
    await run_in_threadpool(catalog.delete_run, db, store, actor, run_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
