"""Known discontinuities of the track (reference data): switches, crossings, bridges, joints, welds.

An asset sits at ``km`` (a point asset) or over ``km``–``km_to`` (a bridge) on a line,
on one track or on every track of the line (``track`` NULL); ``lon``/``lat`` (WGS84,
degrees) where the import carried a geometry.
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import Float, Index, Integer, String
from sqlalchemy.orm import Mapped, mapped_column

from app.db.models.base import Base, UTCDateTime, utcnow

__all__ = ["Asset"]


class Asset(Base):
    """One known discontinuity at ``km`` (to ``km_to`` for an extended one); ``type`` one of
    :data:`app.analysis.condition.discontinuities.ASSET_TYPES`."""

    __tablename__ = "assets"
    __table_args__ = (Index("ix_assets_line_id_track_km", "line_id", "track", "km"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    line_id: Mapped[str] = mapped_column(String(128))
    track: Mapped[str | None] = mapped_column(String(64))
    type: Mapped[str] = mapped_column(String(32))
    km: Mapped[float] = mapped_column(Float)
    km_to: Mapped[float | None] = mapped_column(Float)
    name: Mapped[str | None] = mapped_column(String(200))
    lon: Mapped[float | None] = mapped_column(Float)
    lat: Mapped[float | None] = mapped_column(Float)
    imported_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
