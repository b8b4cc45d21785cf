"""Reference data: import (CSV/Parquet, validated, one transaction; engineer, audited) and
queries (:mod:`app.reference.service`).

``POST /reference/{kind}`` (multipart ``file``; ``mode=append|replace``, ``confirm``), ``DELETE
/reference/{kind}?line_id=``; ``GET /reference/{subsidence,maintenance,superstructure}``.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import asdict, dataclass
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, File, Query, UploadFile
from starlette.concurrency import run_in_threadpool

from app.api.deps import DbDep, EngineerActor, SettingsDep, check_km, km_query
from app.api.errors import ApiError
from app.api.schemas.reference import (
    DeleteOut,
    ImportOut,
    MaintenanceList,
    SubsidenceList,
    SuperstructureList,
)
from app.core.i18n import _
from app.io.reference import MAINTENANCE_TYPES
from app.reference import service
from app.reference.service import Kind

__all__ = ["router"]

router = APIRouter(prefix="/reference", tags=["reference data"])

LineQ = Annotated[str | None, Query(max_length=128, description="Line id")]
TrackQ = Annotated[str | None, Query(max_length=64, description="Track")]
KmFromQ = Annotated[float | None, km_query("Lower km bound")]
KmToQ = Annotated[float | None, km_query("Upper km bound")]


@router.post("/{kind}", response_model=ImportOut, status_code=201,
             summary="Import reference data (CSV or Parquet)",
             responses={409: {"description": "mode=replace over a line with runs without confirm=true"}})
async def import_reference(
    kind: Kind,
    actor: EngineerActor,
    db: DbDep,
    settings: SettingsDep,
    file: Annotated[UploadFile, File(description="CSV or Parquet file")],
    format: Annotated[Literal["csv", "parquet"] | None, Query(description="default: from the file name")] = None,
    mode: Annotated[Literal["append", "replace"], Query(
        description="replace: first delete the stored rows of the lines/tracks in the file")] = "append",
    confirm: Annotated[bool, Query(
        description="with mode=replace over a line and track that has runs: replace all the same "
        "(without it: 409 naming the line and how many runs it has)")] = False,
) -> ImportOut:
    """Validate the whole file, then insert all rows in one transaction.

    Any bad value answers 422 naming the row (1 = first data row) and the
    column; nothing is imported then. ``mode=replace`` over a line and track
    that has runs answers 409 (``confirm``) unless ``confirm=true``.
    """
    cap = settings.max_reference_bytes
    data = await file.read(cap + 1)
    if len(data) > cap:
        raise ApiError(413, "file", _("exceeds the size limit of {cap} bytes (TRACKVKF_MAX_REFERENCE_BYTES)", cap=cap))
    imported, replaced = await run_in_threadpool(
        lambda: service.import_reference(db, settings, actor, kind, data, fmt=format, filename=file.filename,
                                         mode=mode, confirm=confirm))  # RunFileError: 422; 409
    return ImportOut(kind=kind, imported=imported, replaced=replaced)


@router.delete("/{kind}", response_model=DeleteOut, summary="Delete reference data of a line")
def delete_reference(kind: Kind, actor: EngineerActor, db: DbDep,
                     line_id: Annotated[str, Query(max_length=128)], track: TrackQ = None) -> DeleteOut:
    """Delete the rows of ``kind`` of a line (and track)."""
    return DeleteOut(kind=kind, deleted=service.delete_reference(db, actor, kind, line_id, track))


@dataclass(frozen=True)
class _Window:
    """The query of the reference lists: line, track and km range, as given."""

    line_id: str | None
    track: str | None
    km_from: float | None
    km_to: float | None


def _window_query(line_id: LineQ = None, track: TrackQ = None,
                  km_from: KmFromQ = None, km_to: KmToQ = None) -> _Window:
    return _Window(line_id, track, km_from, km_to)


WindowQuery = Annotated[_Window, Depends(_window_query)]


def _query(db, settings, kind, window: _Window, **kw) -> dict[str, Any]:
    """``items`` of ``kind`` in ``window`` (422 for bad km bounds), at most ``max_profile_rows``
    of them, and whether there were more (``truncated``)."""
    check_km(window.km_from, window.km_to)
    return service.reference_window(db, kind, limit=settings.max_profile_rows, **asdict(window), **kw)


@router.get("/subsidence", response_model=SubsidenceList, summary="Subsidence measurements")
def list_subsidence(db: DbDep, settings: SettingsDep, window: WindowQuery) -> SubsidenceList:
    """Subsidence (mm) along km; at most ``TRACKVKF_MAX_PROFILE_ROWS`` rows (``truncated``)."""
    return SubsidenceList(**_query(db, settings, "subsidence", window))


@router.get("/maintenance", response_model=MaintenanceList, summary="Maintenance actions")
def list_maintenance(
    db: DbDep, settings: SettingsDep, window: WindowQuery,
    type: Annotated[str | None, Query(description="comma-separated types")] = None,
    since: Annotated[dt.date | None, Query(description="actions on or after this date")] = None,
) -> MaintenanceList:
    """Maintenance actions overlapping the km range."""
    return MaintenanceList(**_query(db, settings, "maintenance", window, types=parse_types(type), since=since))


@router.get("/superstructure", response_model=SuperstructureList, summary="Superstructure sections")
def list_superstructure(db: DbDep, settings: SettingsDep, window: WindowQuery) -> SuperstructureList:
    """Superstructure sections overlapping the km range."""
    return SuperstructureList(**_query(db, settings, "superstructure", window))


def parse_types(value: str | None) -> list[str] | None:
    """Comma-separated maintenance types → list (422 naming an unknown one)."""
    if value is None or not value.strip():
        return None
    out = []
    for part in value.split(","):
        t = part.strip().lower().replace(" ", "_").replace("-", "_")
        if t not in MAINTENANCE_TYPES:
            raise ApiError(422, "type", _("{type} is not one of {choices}", type=repr(part.strip()), choices=', '.join(MAINTENANCE_TYPES)))
        out.append(t)
    return out
