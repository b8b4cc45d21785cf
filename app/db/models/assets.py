"""Known discontinuities of the track (reference data): switches, crossings, bridges, joints, welds.

An asset sits at ``km`` (a point asset) or over ``km``–``km_to`` (a bridge) on a line,
on one track or on every track of the line (``track`` NULL); ``lon``/``lat`` (WGS84,
degrees) where the import carried a geometry.

An import writes its rows in bounded batches under its own ``import_id`` (an
:class:`AssetImport`, state ``writing``): invisible until one short transaction
points each of its (line, track) pairs at it (:class:`AssetLine`). A row is
**live** when its pair's pointer names its import; the rows of the import a
pair pointed at before are deleted afterwards, in batches (``app.assets.store``).
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import Float, Index, Integer, String
from sqlalchemy.orm import Mapped, mapped_column

from app.db.models.base import Base, UTCDateTime, utcnow

__all__ = ["Asset", "AssetImport", "AssetLine", "ASSET_IMPORT_STATES", "NO_TRACK"]

#: states of an import: its rows being written, switched live, or abandoned (its rows are garbage)
ASSET_IMPORT_STATES = ("writing", "live", "abandoned")
#: the pointer's track of the assets without a track (on every track of their line)
NO_TRACK = ""


class Asset(Base):
    """One known discontinuity at ``km`` (to ``km_to`` for an extended one); ``type`` one of
    :data:`app.analysis.condition.discontinuities.ASSET_TYPES`."""

    __tablename__ = "assets"
    __table_args__ = (Index("ix_assets_line_id_track_km", "line_id", "track", "km"),
                      Index("ix_assets_import_id", "import_id"))

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
    #: the import that wrote it (:class:`AssetImport`); live while its pair's :class:`AssetLine` names it
    import_id: Mapped[int] = mapped_column(Integer, default=0)


class AssetImport(Base):
    """One asset import: who, when, how many rows, and its state (:data:`ASSET_IMPORT_STATES`)."""

    __tablename__ = "asset_imports"
    __table_args__ = ({"sqlite_autoincrement": True},)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    state: Mapped[str] = mapped_column(String(16), default="writing")
    n_rows: Mapped[int] = mapped_column(Integer, default=0)
    created_by: Mapped[str | None] = mapped_column(String(128))
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class AssetLine(Base):
    """Which import's rows are live on a line and track (``track`` :data:`NO_TRACK`: the assets on
    every track of the line), their number and their longest extent (km; 0 for point assets), which
    bounds the km window a reader of a place's assets looks in."""

    __tablename__ = "asset_lines"

    line_id: Mapped[str] = mapped_column(String(128), primary_key=True)
    track: Mapped[str] = mapped_column(String(64), primary_key=True)
    import_id: Mapped[int] = mapped_column(Integer)
    n_assets: Mapped[int] = mapped_column(Integer, default=0)
    max_extent_km: Mapped[float] = mapped_column(Float, default=0.0)
