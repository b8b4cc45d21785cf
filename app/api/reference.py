"""Reference data: import (CSV/Parquet, validated, one transaction) and queries.

``POST /reference/{kind}`` (multipart ``file``; ``mode=append|replace``) —
writes: to be restricted to the engineer role by the access control.
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
from app.audit import record
from app.db import reference_crud
from app.io.isolation import read_reference_upload
from app.io.reference import MAINTENANCE_TYPES

__all__ = ["router"]

router = APIRouter(prefix="/reference", tags=["reference data"])

Kind = Literal["subsidence", "maintenance", "superstructure"]
LineQ = Annotated[str | None, Query(max_length=128, description="Line id")]
TrackQ = Annotated[str | None, Query(max_length=64, description="Track")]
KmFromQ = Annotated[float | None, km_query("Lower km bound")]
KmToQ = Annotated[float | None, km_query("Upper km bound")]


@router.post("/{kind}", response_model=ImportOut, status_code=201,
             summary="Import reference data (CSV or Parquet)")
async def import_reference(
    kind: Kind,
    actor: EngineerActor,
    db: DbDep,
    settings: SettingsDep,
    file: Annotated[UploadFile, File(description="CSV or Parquet file")],
    format: Annotated[Literal["csv", "parquet"] | None, Query(description="default: from the file name")] = None,
    mode: Annotated[Literal["append", "replace"], Query(
        description="replace: first delete the stored rows of the lines/tracks in the file")] = "append",
) -> ImportOut:
    """Validate the whole file, then insert all rows in one transaction.

    Any bad value answers 422 naming the row (1 = first data row) and the
    column; nothing is imported then.
    """
    cap = settings.max_reference_bytes
    data = await file.read(cap + 1)
    if len(data) > cap:
        raise ApiError(413, "file", f"exceeds the size limit of {cap} bytes (TRACKVKF_MAX_REFERENCE_BYTES)")
    rows = await run_in_threadpool(read_reference_upload, settings, data, kind, format, file.filename)  # RunFileError: 422

    def write() -> tuple[int, int]:
        with db.write() as session:
            replaced = 0
            if mode == "replace":
                for line_id, track in sorted({(r["line_id"], r["track"]) for r in rows}):
                    replaced += reference_crud.delete_reference(session, kind, line_id, track)
            imported = reference_crud.insert_reference(session, kind, rows)
            record(session, actor, "reference.import", target=kind,
                   detail={"imported": imported, "replaced": replaced, "mode": mode,
                           "filename": file.filename})
            return imported, replaced

    imported, replaced = await run_in_threadpool(write)
    return ImportOut(kind=kind, imported=imported, replaced=replaced)


@router.delete("/{kind}", response_model=DeleteOut, summary="Delete reference data of a line")
def delete_reference(kind: Kind, actor: EngineerActor, db: DbDep,
                     line_id: Annotated[str, Query(max_length=128)], track: TrackQ = None) -> DeleteOut:
    """Delete the rows of ``kind`` of a line (and track)."""
    with db.write() as session:
        n = reference_crud.delete_reference(session, kind, line_id, track)
        record(session, actor, "reference.delete", target=kind,
               detail={"line_id": line_id, "track": track, "deleted": n})
    return DeleteOut(kind=kind, deleted=n)


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
    limit = settings.max_profile_rows
    with db.read() as session:
        rows = reference_crud.reference_records(session, kind, limit=limit + 1, **asdict(window), **kw)
    return {"items": rows[:limit], "truncated": len(rows) > limit}


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
            raise ApiError(422, "type", f"{part.strip()!r} is not one of {', '.join(MAINTENANCE_TYPES)}")
        out.append(t)
    return out
