"""Schemas of channel maps and line geometries."""

from __future__ import annotations

import datetime as dt
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from app.api.schemas.text import Text

__all__ = [
    "ChannelMapIn",
    "ChannelMapOut",
    "ChannelMapList",
    "GeometrySummary",
    "GeometryList",
    "GeometryOut",
    "GeometryImportOut",
    "IndicatorSegment",
    "IndicatorOut",
]


class ChannelMapIn(BaseModel):
    """A channel map to store for a vehicle (see docs/run-format.md)."""

    model_config = ConfigDict(extra="forbid")

    vehicle_id: Text = Field(min_length=1, max_length=128,
                            description="Vehicle the map belongs to")
    name: Text = Field(min_length=1, max_length=200, description="Name, unique per vehicle")
    channels: dict[str, Any] = Field(
        description='trackvkf channel → recorder channel: "name" or {"source", "group", "unit"}'
    )


class ChannelMapOut(BaseModel):
    """A stored channel map."""

    id: int
    vehicle_id: str
    name: str
    channels: dict[str, Any]
    created_by: str | None = None
    created_at: dt.datetime
    updated_at: dt.datetime


class ChannelMapList(BaseModel):
    """Stored channel maps."""

    items: list[ChannelMapOut]


class GeometrySummary(BaseModel):
    """A stored line geometry without its vertices."""

    id: int
    line_id: str
    track: str
    source_crs: str = Field(description="CRS the imported file declared")
    n_vertices: int
    length_m: float = Field(description="Geometric length, m")
    km_from: float = Field(description="Km at the first vertex")
    km_to: float = Field(description="Km at the last vertex")
    imported_by: str | None = None
    imported_at: dt.datetime


class GeometryList(BaseModel):
    """Stored line geometries."""

    items: list[GeometrySummary]


class GeometryImportOut(BaseModel):
    """Result of a geometry import."""

    imported: list[GeometrySummary]


class GeometryOut(GeometrySummary):
    """A line geometry with its vertices: WGS84 and a local plane (m) for maps without tiles."""

    lon: list[float] = Field(description="Longitude of every vertex, degrees (WGS84)")
    lat: list[float] = Field(description="Latitude of every vertex, degrees (WGS84)")
    x_m: list[float] = Field(description="East of the line's centre, m (azimuthal equidistant)")
    y_m: list[float] = Field(description="North of the line's centre, m")
    km: list[float] = Field(description="Line km of every vertex")


class IndicatorSegment(BaseModel):
    """One segment of the line with the coloured quantity."""

    km_from: float
    km_to: float
    km: float = Field(description="Centre, km")
    value: float | None = Field(description="Mean of the quantity over the segment's bins and wheels")
    lon: float
    lat: float
    x_m: float
    y_m: float


class IndicatorOut(BaseModel):
    """A quantity of a run's profile placed along the line geometry."""

    geometry_id: int
    line_id: str
    track: str
    run_id: int | None = Field(description="The run shown (default: the line's latest processed run)")
    quantity: str
    unit: str
    segment_m: float
    segments: list[IndicatorSegment]
