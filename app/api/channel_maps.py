"""Channel maps per vehicle: CRUD (engineer writes, audited: :mod:`app.runs.channel_maps`);
selected at upload by id."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Path, Query, Response, status

from app.api.deps import DbDep, EngineerActor, require_role
from app.api.schemas.recorder import ChannelMapIn, ChannelMapList, ChannelMapOut
from app.core.ids import MAX_ID
from app.runs import channel_maps as service

__all__ = ["router"]

router = APIRouter(prefix="/channel-maps", tags=["channel maps"])
MapId = Annotated[int, Path(ge=1, le=MAX_ID, description="Channel map id")]


def _out(row) -> ChannelMapOut:
    return ChannelMapOut(
        id=row.id, vehicle_id=row.vehicle_id, name=row.name, channels=dict(row.channels),
        created_by=row.created_by, created_at=row.created_at, updated_at=row.updated_at,
    )


@router.get("", response_model=ChannelMapList, summary="List channel maps")
def list_channel_maps(
    db: DbDep, vehicle_id: Annotated[str | None, Query(max_length=128)] = None
) -> ChannelMapList:
    """Stored channel maps, of one vehicle if given."""
    return ChannelMapList(items=[_out(r) for r in service.channel_maps(db, vehicle_id)])


@router.post("", response_model=ChannelMapOut, status_code=201, summary="Store a channel map (engineer)",
             dependencies=[Depends(require_role("engineer"))])
def create_channel_map(body: ChannelMapIn, db: DbDep, actor: EngineerActor) -> ChannelMapOut:
    """Validate and store a channel map; 409 if the vehicle has one of that name."""
    return _out(service.create_channel_map(db, actor, body.vehicle_id, body.name, body.channels))


@router.get("/{map_id}", response_model=ChannelMapOut, summary="A channel map")
def get_channel_map(map_id: MapId, db: DbDep) -> ChannelMapOut:
    """One stored channel map."""
    return _out(service.channel_map(db, map_id))


@router.put("/{map_id}", response_model=ChannelMapOut, summary="Replace a channel map (engineer)",
            dependencies=[Depends(require_role("engineer"))])
def update_channel_map(map_id: MapId, body: ChannelMapIn, db: DbDep, actor: EngineerActor) -> ChannelMapOut:
    """Replace vehicle, name and channels of a stored map."""
    return _out(service.replace_channel_map(db, actor, map_id, body.vehicle_id, body.name, body.channels))


@router.delete("/{map_id}", status_code=status.HTTP_204_NO_CONTENT,
               summary="Delete a channel map (engineer)", dependencies=[Depends(require_role("engineer"))])
def delete_channel_map(map_id: MapId, db: DbDep, actor: EngineerActor) -> Response:
    """Delete a stored map (runs ingested with it keep the channel sources in their report)."""
    service.delete_channel_map(db, actor, map_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
