"""Tables for recorder input: channel maps per vehicle and line geometries per line and track."""

from __future__ import annotations

import datetime as dt
from typing import Any

from sqlalchemy import Float, Integer, String, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column

from app.db.models.base import Base, JSONType, UTCDateTime, utcnow

__all__ = ["ChannelMapRow", "LineGeometryRow"]


class ChannelMapRow(Base):
    """A channel map (:class:`app.io.channel_map.ChannelMap`) of one vehicle, by name."""

    __tablename__ = "channel_maps"
    __table_args__ = (UniqueConstraint("vehicle_id", "name"), {"sqlite_autoincrement": True})

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    vehicle_id: Mapped[str] = mapped_column(String(128), index=True)
    name: Mapped[str] = mapped_column(String(200))
    channels: Mapped[dict[str, Any]] = mapped_column(JSONType)
    created_by: Mapped[str | None] = mapped_column(String(128))
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    updated_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class LineGeometryRow(Base):
    """The geometry of one track of a line: WGS84 vertices and km stations."""

    __tablename__ = "line_geometries"
    __table_args__ = (UniqueConstraint("line_id", "track"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    line_id: Mapped[str] = mapped_column(String(128))
    track: Mapped[str] = mapped_column(String(64))
    source_crs: Mapped[str] = mapped_column(String(200))
    coordinates: Mapped[list[list[float]]] = mapped_column(JSONType)
    km: Mapped[list[float]] = mapped_column(JSONType)
    length_m: Mapped[float] = mapped_column(Float)
    imported_by: Mapped[str | None] = mapped_column(String(128))
    imported_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
