"""Channel maps per vehicle (which recorder channel is which signal of a run), administered by
engineers and selected at upload by id: each change validated (:func:`app.io.channel_map.parse_channel_map`,
422 naming the channel) and written with its audit entry in one transaction. Rows are answered
detached (their columns loaded)."""

from __future__ import annotations

from typing import Any

from sqlalchemy.exc import IntegrityError

from app.audit import record
from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.core.security import Actor
from app.db import recorder_crud
from app.db.models import ChannelMapRow
from app.db.session import Database
from app.io.channel_map import parse_channel_map

__all__ = ["channel_maps", "channel_map", "create_channel_map", "replace_channel_map", "delete_channel_map"]


def _validated(name: str, channels: dict[str, Any]) -> dict:
    """The channels as stored; a :class:`~app.io.RunFileError` (422) names the channel at fault."""
    cmap = parse_channel_map({"name": name, "channels": channels})
    return cmap.model_dump(mode="json", exclude_none=True)["channels"]


def _taken(vehicle_id: str, name: str) -> ApiError:
    return ApiError(409, "name", _("vehicle {vehicle_id} already has a map {name}", vehicle_id=repr(vehicle_id), name=repr(name)))


def channel_maps(db: Database, vehicle_id: str | None = None) -> list[ChannelMapRow]:
    """The stored channel maps, of one vehicle if given."""
    with db.read() as session:
        return recorder_crud.list_channel_maps(session, vehicle_id)


def channel_map(db: Database, map_id: int) -> ChannelMapRow:
    """One stored channel map; 404 naming ``channel_map``."""
    with db.read() as session:
        row = recorder_crud.get_channel_map(session, map_id)
        if row is None:
            raise not_found("channel_map", map_id)
        return row


def create_channel_map(db: Database, actor: Actor, vehicle_id: str, name: str,
                       channels: dict[str, Any]) -> ChannelMapRow:
    """Validate and store a channel map (audited ``channel_map.create``).

    Raises
    ------
    ApiError
        409 (``name``) when the vehicle has a map of that name; 422 naming a bad channel.
    """
    stored = _validated(name, channels)
    try:
        with db.write() as session:
            if recorder_crud.find_channel_map(session, vehicle_id, name) is not None:
                raise _taken(vehicle_id, name)
            row = recorder_crud.save_channel_map(session, None, vehicle_id=vehicle_id, name=name, channels=stored,
                                                 by=actor.name)
            record(session, actor, "channel_map.create", target=row.id,
                   detail={"vehicle_id": vehicle_id, "name": name})
            return row
    except IntegrityError:  # the same name stored concurrently
        raise _taken(vehicle_id, name) from None


def replace_channel_map(db: Database, actor: Actor, map_id: int, vehicle_id: str, name: str,
                        channels: dict[str, Any]) -> ChannelMapRow:
    """Replace vehicle, name and channels of a stored map (audited ``channel_map.update``).

    Raises
    ------
    ApiError
        404 naming ``channel_map``; 409 (``name``) when another map of the vehicle has that name;
        422 naming a bad channel.
    """
    stored = _validated(name, channels)
    try:
        with db.write() as session:
            row = recorder_crud.get_channel_map(session, map_id)
            if row is None:
                raise not_found("channel_map", map_id)
            other = recorder_crud.find_channel_map(session, vehicle_id, name)
            if other is not None and other.id != map_id:
                raise _taken(vehicle_id, name)
            recorder_crud.save_channel_map(session, row, vehicle_id=vehicle_id, name=name, channels=stored,
                                           by=actor.name)
            record(session, actor, "channel_map.update", target=map_id,
                   detail={"vehicle_id": vehicle_id, "name": name})
            return row
    except IntegrityError:
        raise _taken(vehicle_id, name) from None


def delete_channel_map(db: Database, actor: Actor, map_id: int) -> None:
    """Delete a stored map (audited ``channel_map.delete``; runs ingested with it keep the channel
    sources in their report); 404 naming ``channel_map``."""
    with db.write() as session:
        if not recorder_crud.delete_channel_map(session, map_id):
            raise not_found("channel_map", map_id)
        record(session, actor, "channel_map.delete", target=map_id)
