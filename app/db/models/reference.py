"""Reference data tables: subsidence measurements, maintenance actions, superstructure sections.

Positions are line km (``km``, or ``km_from``–``km_to``) on a line and track,
as the asset database and the subsidence vehicle report them.
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import Date, Float, Index, Integer, SmallInteger, String, Text
from sqlalchemy.orm import Mapped, mapped_column

from app.db.models.base import Base, UTCDateTime, utcnow

__all__ = ["SubsidenceMeasurement", "MaintenanceAction", "SuperstructureSection", "MAINTENANCE_TYPES"]

#: Allowed maintenance action types.
MAINTENANCE_TYPES: tuple[str, ...] = ("tamping", "grinding", "rail_replacement", "ballast_cleaning", "other")


class SubsidenceMeasurement(Base):
    """One subsidence value (mm, negative = down) at a km, optionally of one rail (1 right, 2 left)."""

    __tablename__ = "ref_subsidence"
    __table_args__ = (Index("ix_ref_subsidence_line_id_track_km", "line_id", "track", "km"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    line_id: Mapped[str] = mapped_column(String(128))
    track: Mapped[str] = mapped_column(String(64))
    km: Mapped[float] = mapped_column(Float)
    rail: Mapped[int | None] = mapped_column(SmallInteger)
    subsidence_mm: Mapped[float] = mapped_column(Float)
    date: Mapped[dt.date] = mapped_column(Date)
    imported_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class MaintenanceAction(Base):
    """One maintenance action over ``km_from``–``km_to`` on a date."""

    __tablename__ = "ref_maintenance"
    __table_args__ = (Index("ix_ref_maintenance_line_id_track_km_from", "line_id", "track", "km_from"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    line_id: Mapped[str] = mapped_column(String(128))
    track: Mapped[str] = mapped_column(String(64))
    km_from: Mapped[float] = mapped_column(Float)
    km_to: Mapped[float] = mapped_column(Float)
    type: Mapped[str] = mapped_column(String(32))
    date: Mapped[dt.date] = mapped_column(Date)
    imported_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class SuperstructureSection(Base):
    """A section of one superstructure type over ``km_from``–``km_to``."""

    __tablename__ = "ref_superstructure"
    __table_args__ = (Index("ix_ref_superstructure_line_id_track_km_from", "line_id", "track", "km_from"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    line_id: Mapped[str] = mapped_column(String(128))
    track: Mapped[str] = mapped_column(String(64))
    km_from: Mapped[float] = mapped_column(Float)
    km_to: Mapped[float] = mapped_column(Float)
    type: Mapped[str] = mapped_column(String(64))
    details: Mapped[str | None] = mapped_column(Text)
    imported_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
