"""Line geometries: GeoJSON import (engineer, audited), vertices, and a profile quantity along them."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, File, Path, Query, Response, UploadFile, status
from starlette.concurrency import run_in_threadpool

from app.api.deps import DbDep, EngineerActor, SettingsDep, require_role
from app.api.errors import ApiError
from app.api.schemas.recorder import (
    GeometryImportOut,
    GeometryList,
    GeometryOut,
    GeometrySummary,
    IndicatorOut,
)
from app.core.i18n import _
from app.core.ids import MAX_ID
from app.maps import geometries as service
from app.maps import indicator as map_indicator
from app.maps.indicator import DEFAULT_MAP_SEGMENT_M, INDICATOR_UNITS

__all__ = ["router", "INDICATOR_UNITS"]

router = APIRouter(prefix="/geometry", tags=["line geometry"])
GeometryId = Annotated[int, Path(ge=1, le=MAX_ID, description="Geometry id")]

def _summary(row) -> GeometrySummary:
    return GeometrySummary(
        id=row.id, line_id=row.line_id, track=row.track, source_crs=row.source_crs,
        n_vertices=len(row.km), length_m=row.length_m, km_from=row.km[0], km_to=row.km[-1],
        imported_by=row.imported_by, imported_at=row.imported_at,
    )


@router.post("", response_model=GeometryImportOut, status_code=201,
             summary="Import line geometries (GeoJSON with km stations; engineer)",
             dependencies=[Depends(require_role("engineer"))])
async def import_geometry(
    actor: EngineerActor,
    db: DbDep,
    settings: SettingsDep,
    file: Annotated[UploadFile, File(description="GeoJSON FeatureCollection (see docs/positioning.md)")],
) -> GeometryImportOut:
    """Validate every feature, then store them in one transaction (replacing the same line/track).

    A feature without km stations, with stations that are not monotonic or
    disagree with its length, or coordinates in an unknown CRS answers 422
    naming the feature (``features[i]``) or ``crs``; nothing is stored then.
    """
    cap = settings.max_reference_bytes
    data = await file.read(cap + 1)
    if len(data) > cap:
        raise ApiError(413, "file", _("exceeds the size limit of {cap} bytes (TRACKVKF_MAX_REFERENCE_BYTES)", cap=cap))
    rows = await run_in_threadpool(service.import_geometries, db, settings, actor, data, file.filename)
    return GeometryImportOut(imported=[_summary(r) for r in rows])


@router.get("", response_model=GeometryList, summary="List line geometries")
def list_geometry(db: DbDep, line_id: Annotated[str | None, Query(max_length=128)] = None) -> GeometryList:
    """Stored geometries (without vertices)."""
    return GeometryList(items=[_summary(r) for r in service.geometries(db, line_id)])


@router.get("/{geometry_id}", response_model=GeometryOut, summary="A line geometry with its vertices")
def get_geometry(geometry_id: GeometryId, db: DbDep) -> GeometryOut:
    """Vertices in WGS84 and in a local metric plane centred on the line (for maps without tiles)."""
    row, geom = service.geometry(db, geometry_id)
    pl = geom.polyline()
    return GeometryOut(**_summary(row).model_dump(), lon=geom.lon.tolist(), lat=geom.lat.tolist(),
                       x_m=pl.x.tolist(), y_m=pl.y.tolist(), km=geom.km.tolist())


@router.delete("/{geometry_id}", status_code=status.HTTP_204_NO_CONTENT,
               summary="Delete a line geometry (engineer)", dependencies=[Depends(require_role("engineer"))])
def delete_geometry(geometry_id: GeometryId, db: DbDep, actor: EngineerActor) -> Response:
    """Delete a stored geometry (runs placed with it keep their km)."""
    service.delete_geometry(db, actor, geometry_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get("/{geometry_id}/indicator", response_model=IndicatorOut,
            summary="A profile quantity of a run along the line geometry")
def geometry_indicator(
    geometry_id: GeometryId,
    db: DbDep,
    settings: SettingsDep,
    quantity: Annotated[str, Query(max_length=64, description=(
        "stiffness_index (ln(A / A_ref(class, v)) by the line's reference curves) or a profile column "
        "to colour the line by"))] = "sleeper_amp",
    run_id: Annotated[int | None, Query(ge=1, le=MAX_ID, description="Default: the latest processed run of the line and track")] = None,
    segment_m: Annotated[float, Query(ge=10.0, le=10_000.0, description="Segment length, m")] = DEFAULT_MAP_SEGMENT_M,
) -> IndicatorOut:
    """Mean of ``quantity`` over the bins and wheels of each segment of the run, placed on the line.

    Segments without profile rows have ``value`` null; a quantity that is not
    a profile column answers 422 naming ``quantity``.
    """
    return IndicatorOut(**map_indicator.geometry_indicator(db, geometry_id, quantity=quantity, run_id=run_id,
                                                           segment_m=segment_m, settings=settings))
