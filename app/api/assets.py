"""Known discontinuities (assets): ``GET /assets``, ``POST /assets`` (CSV or GeoJSON; engineer),
``DELETE /assets/{id}`` (admin). An import replaces the stored assets of each line and track
it holds (the asset register is the truth): :func:`app.assets.service.import_assets`."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, File, Path, Query, Response, UploadFile, status
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from app.analysis.condition.discontinuities import ASSET_TYPES
from app.api.deps import AdminActor, DbDep, EngineerActor, SettingsDep, require_role
from app.api.errors import ApiError, not_found
from app.assets import service
from app.core.i18n import _
from app.core.ids import MAX_ID

__all__ = ["router"]

router = APIRouter(prefix="/assets", tags=["assets (known discontinuities)"])

AssetId = Annotated[int, Path(ge=1, le=MAX_ID)]


class AssetOut(BaseModel):
    id: int
    line_id: str
    track: str | None = Field(description="null: on every track of the line")
    type: str = Field(description=", ".join(ASSET_TYPES))
    km: float
    km_to: float | None = Field(description="end of an extended asset (a bridge), km")
    name: str | None
    lon: float | None = Field(description="WGS84, degrees (GeoJSON imports)")
    lat: float | None


class AssetList(BaseModel):
    items: list[AssetOut]
    total: int


class AssetImportOut(BaseModel):
    imported: int = Field(description="assets imported")
    replaced: int = Field(description="assets of the same lines and tracks deleted first")


@router.get("", response_model=AssetList, summary="Known discontinuities (assets)")
def list_assets(
    db: DbDep,
    line_id: Annotated[str | None, Query(max_length=128)] = None,
    track: Annotated[str | None, Query(max_length=64, description="assets without a track are on every track")] = None,
    type: Annotated[str | None, Query(max_length=32, description=", ".join(ASSET_TYPES))] = None,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 10_000,
    offset: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> AssetList:
    """Assets by line, track and km."""
    if type is not None and type not in ASSET_TYPES:
        raise ApiError(422, "type", _("{type} is not one of {choices}", type=repr(type), choices=', '.join(ASSET_TYPES)))
    items, total = service.find_assets(db, line_id=line_id, track=track, type_=type, limit=limit, offset=offset)
    return AssetList(items=[AssetOut(**a) for a in items], total=total)


@router.post("", response_model=AssetImportOut, status_code=201, summary="Import assets (CSV or GeoJSON; engineer)")
async def import_assets(
    actor: EngineerActor,
    db: DbDep,
    settings: SettingsDep,
    file: Annotated[UploadFile, File(description="CSV (line_id,track,type,km[,km_to,name]) or GeoJSON")],
) -> AssetImportOut:
    """Validate the whole file, then replace the assets of its lines and tracks: written in short
    batches, live at once in one short transaction with the audit entry (docs/security.md,
    "What an import may hold").

    A bad value answers 422 naming the row (CSV, 1 = first data row) or feature (GeoJSON) and
    the column; nothing is imported then. A file beyond ``TRACKVKF_ASSETS_IMPORT_MAX_ROWS`` rows
    or ``TRACKVKF_ASSETS_IMPORT_MAX_LINES`` lines and tracks answers 413.
    """
    cap = settings.max_reference_bytes
    data = await file.read(cap + 1)
    if len(data) > cap:
        raise ApiError(413, "file", _("exceeds the size limit of {cap} bytes (TRACKVKF_MAX_REFERENCE_BYTES)", cap=cap))
    got = await run_in_threadpool(service.import_assets, db, settings, actor, data, file.filename)
    return AssetImportOut(imported=got["imported"], replaced=got["replaced"])


@router.delete("/{asset_id}", status_code=status.HTTP_204_NO_CONTENT, summary="Delete an asset (admin)",
               dependencies=[Depends(require_role("admin"))])
def delete_asset(asset_id: AssetId, db: DbDep, actor: AdminActor) -> Response:
    """Delete one asset."""
    if not service.remove_asset(db, actor, asset_id):
        raise not_found("asset", asset_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
