"""Queries of the recorder-input tables: channel maps and line geometries."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from sqlalchemy import delete, desc, select
from sqlalchemy.orm import Session

from app.db.models import ChannelMapRow, Job, JobStatus, LineGeometryRow, Run, utcnow
from app.io.geometry import LineGeometry

__all__ = [
    "list_channel_maps",
    "get_channel_map",
    "find_channel_map",
    "save_channel_map",
    "delete_channel_map",
    "upsert_geometries",
    "list_geometries",
    "get_geometry",
    "find_geometry",
    "delete_geometry",
    "to_line_geometry",
    "latest_processed_run",
]


def list_channel_maps(session: Session, vehicle_id: str | None = None) -> list[ChannelMapRow]:
    """Channel maps, of one vehicle if given, by vehicle and name."""
    stmt = select(ChannelMapRow).order_by(ChannelMapRow.vehicle_id, ChannelMapRow.name)
    if vehicle_id is not None:
        stmt = stmt.where(ChannelMapRow.vehicle_id == vehicle_id)
    return list(session.scalars(stmt))


def get_channel_map(session: Session, map_id: int) -> ChannelMapRow | None:
    """The channel map with this id, or None."""
    return session.get(ChannelMapRow, map_id)


def find_channel_map(session: Session, vehicle_id: str, name: str) -> ChannelMapRow | None:
    """The channel map of a vehicle with this name, or None."""
    return session.scalar(
        select(ChannelMapRow).where(ChannelMapRow.vehicle_id == vehicle_id, ChannelMapRow.name == name)
    )


def save_channel_map(
    session: Session,
    row: ChannelMapRow | None,
    *,
    vehicle_id: str,
    name: str,
    channels: dict[str, Any],
    by: str,
) -> ChannelMapRow:
    """Create a channel map (``row`` None) or replace the content of ``row``; flushed."""
    now = utcnow()
    if row is None:
        row = ChannelMapRow(vehicle_id=vehicle_id, name=name, channels=channels, created_by=by,
                            created_at=now, updated_at=now)
        session.add(row)
    else:
        row.vehicle_id, row.name, row.channels, row.updated_at = vehicle_id, name, channels, now
    session.flush()
    return row


def delete_channel_map(session: Session, map_id: int) -> bool:
    """Delete a channel map; whether it existed."""
    return bool(session.execute(delete(ChannelMapRow).where(ChannelMapRow.id == map_id)).rowcount)


def upsert_geometries(session: Session, geometries: Sequence[LineGeometry], by: str) -> list[LineGeometryRow]:
    """Store geometries, replacing a stored one of the same line and track; flushed."""
    rows = []
    for g in geometries:
        row = find_geometry(session, g.line_id, g.track)
        if row is None:
            row = LineGeometryRow(line_id=g.line_id, track=g.track)
            session.add(row)
        row.source_crs = g.source_crs
        row.coordinates = [[float(a), float(b)] for a, b in zip(g.lon, g.lat, strict=True)]
        row.km = [float(k) for k in g.km]
        row.length_m = g.length_m
        row.imported_by = by
        row.imported_at = utcnow()
        rows.append(row)
    session.flush()
    return rows


def list_geometries(session: Session, line_id: str | None = None) -> list[LineGeometryRow]:
    """Stored geometries (of one line if given), by line and track."""
    stmt = select(LineGeometryRow).order_by(LineGeometryRow.line_id, LineGeometryRow.track)
    if line_id is not None:
        stmt = stmt.where(LineGeometryRow.line_id == line_id)
    return list(session.scalars(stmt))


def get_geometry(session: Session, geometry_id: int) -> LineGeometryRow | None:
    """The geometry with this id, or None."""
    return session.get(LineGeometryRow, geometry_id)


def find_geometry(session: Session, line_id: str, track: str) -> LineGeometryRow | None:
    """The geometry of a line and track, or None."""
    return session.scalar(
        select(LineGeometryRow).where(LineGeometryRow.line_id == line_id, LineGeometryRow.track == track)
    )


def delete_geometry(session: Session, geometry_id: int) -> bool:
    """Delete a geometry; whether it existed."""
    return bool(session.execute(delete(LineGeometryRow).where(LineGeometryRow.id == geometry_id)).rowcount)


def to_line_geometry(row: LineGeometryRow) -> LineGeometry:
    """The stored row as the :class:`~app.io.geometry.LineGeometry` map matching uses."""
    coords = np.asarray(row.coordinates, dtype=np.float64)
    return LineGeometry(row.line_id, row.track, coords[:, 0], coords[:, 1],
                        np.asarray(row.km, dtype=np.float64), row.source_crs)


def latest_processed_run(session: Session, line_id: str, track: str) -> Run | None:
    """The run of a line and track with the latest start time that has a done job."""
    return session.scalar(
        select(Run)
        .where(Run.line_id == line_id, Run.track == track)
        .where(select(Job.id).where(Job.run_id == Run.id, Job.status == JobStatus.DONE).exists())
        .order_by(desc(Run.start_time), desc(Run.id))
        .limit(1)
    )
