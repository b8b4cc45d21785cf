"""Channel maps per vehicle: CRUD (engineer writes, audited); selected at upload by id."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Path, Query, Response, status
from sqlalchemy.exc import IntegrityError

from app.api.deps import DbDep, EngineerActor, require_role
from app.api.errors import ApiError, not_found
from app.api.schemas.recorder import ChannelMapIn, ChannelMapList, ChannelMapOut
from app.audit import record
from app.db import recorder_crud
from app.db.models import ChannelMapRow
from app.io.channel_map import parse_channel_map

__all__ = ["router"]

router = APIRouter(prefix="/channel-maps", tags=["channel maps"])
MapId = Annotated[int, Path(ge=1, le=2**31 - 1, description="Channel map id")]


def _out(row: ChannelMapRow) -> ChannelMapOut:
    return ChannelMapOut(
        id=row.id, vehicle_id=row.vehicle_id, name=row.name, channels=dict(row.channels),
        created_by=row.created_by, created_at=row.created_at, updated_at=row.updated_at,
    )


def _validated(body: ChannelMapIn) -> dict:
    cmap = parse_channel_map({"name": body.name, "channels": body.channels})  # RunFileError: 422
    return cmap.model_dump(mode="json", exclude_none=True)["channels"]


@router.get("", response_model=ChannelMapList, summary="List channel maps")
def list_channel_maps(
    db: DbDep, vehicle_id: Annotated[str | None, Query(max_length=128)] = None
) -> ChannelMapList:
    """Stored channel maps, of one vehicle if given."""
    with db.read() as session:
        return ChannelMapList(items=[_out(r) for r in recorder_crud.list_channel_maps(session, vehicle_id)])


@router.post("", response_model=ChannelMapOut, status_code=201, summary="Store a channel map (engineer)",
             dependencies=[Depends(require_role("engineer"))])
def create_channel_map(body: ChannelMapIn, db: DbDep, actor: EngineerActor) -> ChannelMapOut:
    """Validate and store a channel map; 409 if the vehicle has one of that name."""
    channels = _validated(body)
    try:
        with db.write() as session:
            if recorder_crud.find_channel_map(session, body.vehicle_id, body.name) is not None:
                raise ApiError(409, "name", f"vehicle {body.vehicle_id!r} already has a map {body.name!r}")
            row = recorder_crud.save_channel_map(
                session, None, vehicle_id=body.vehicle_id, name=body.name, channels=channels,
                by=actor.name,
            )
            record(session, actor, "channel_map.create", target=row.id,
                   detail={"vehicle_id": body.vehicle_id, "name": body.name})
            return _out(row)
    except IntegrityError:
        raise ApiError(409, "name", f"vehicle {body.vehicle_id!r} already has a map {body.name!r}") from None


@router.get("/{map_id}", response_model=ChannelMapOut, summary="A channel map")
def get_channel_map(map_id: MapId, db: DbDep) -> ChannelMapOut:
    """One stored channel map."""
    with db.read() as session:
        row = recorder_crud.get_channel_map(session, map_id)
        if row is None:
            raise not_found("channel_map", map_id)
        return _out(row)


@router.put("/{map_id}", response_model=ChannelMapOut, summary="Replace a channel map (engineer)",
            dependencies=[Depends(require_role("engineer"))])
def update_channel_map(
    map_id: MapId, body: ChannelMapIn, db: DbDep, actor: EngineerActor
) -> ChannelMapOut:
    """Replace vehicle, name and channels of a stored map."""
    channels = _validated(body)
    try:
        with db.write() as session:
            row = recorder_crud.get_channel_map(session, map_id)
            if row is None:
                raise not_found("channel_map", map_id)
            other = recorder_crud.find_channel_map(session, body.vehicle_id, body.name)
            if other is not None and other.id != map_id:
                raise ApiError(409, "name", f"vehicle {body.vehicle_id!r} already has a map {body.name!r}")
            recorder_crud.save_channel_map(
                session, row, vehicle_id=body.vehicle_id, name=body.name, channels=channels,
                by=actor.name,
            )
            record(session, actor, "channel_map.update", target=map_id,
                   detail={"vehicle_id": body.vehicle_id, "name": body.name})
            return _out(row)
    except IntegrityError:
        raise ApiError(409, "name", f"vehicle {body.vehicle_id!r} already has a map {body.name!r}") from None


@router.delete("/{map_id}", status_code=status.HTTP_204_NO_CONTENT,
               summary="Delete a channel map (engineer)", dependencies=[Depends(require_role("engineer"))])
def delete_channel_map(map_id: MapId, db: DbDep, actor: EngineerActor) -> Response:
    """Delete a stored map (runs ingested with it keep the channel sources in their report)."""
    with db.write() as session:
        if not recorder_crud.delete_channel_map(session, map_id):
            raise not_found("channel_map", map_id)
        record(session, actor, "channel_map.delete", target=map_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
