"""Schemas of wheel out-of-roundness results."""

from __future__ import annotations

import datetime as dt

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["WheelOrderOut", "WheelOut", "WheelList", "WheelTrendPoint", "WheelTrend"]


class WheelOrderOut(BaseModel):
    """One OOR order of a wheel."""

    model_config = ConfigDict(extra="allow")

    order: int
    radius_um: float | None = Field(None, description="Radius deviation amplitude, µm")
    radius_um_p05: float | None = Field(None, description="5th percentile over windows, µm")
    radius_um_p95: float | None = Field(None, description="95th percentile over windows, µm")
    phase_rad: float | None = Field(None, description="Phase referred to wheel angle, rad")
    accel_amp: float | None = Field(None, description="Acceleration amplitude, m/s²")


class WheelOut(BaseModel):
    """Out-of-roundness of one wheel over a run."""

    wheel: str
    job_id: int | None = None
    wheel_diameter_m: float | None = None
    n_windows: int | None = None
    orders: list[WheelOrderOut]
    angles_deg: list[float | None]
    profile_um: list[float | None] = Field(description="Radius deviation r(θ), µm")
    profile_p05_um: list[float | None] | None = None
    profile_p95_um: list[float | None] | None = None


class WheelList(BaseModel):
    """Wheel results of a run."""

    run_id: int
    items: list[WheelOut]


class WheelTrendPoint(BaseModel):
    """OOR of one wheel in one run of a vehicle."""

    run_id: int
    start_time: dt.datetime | None = None
    line_id: str | None = None
    track: str | None = None
    wheel: str
    wheel_diameter_m: float | None = Field(None, description="Diameter from the run metadata, m")
    refined_diameter_m: float | None = Field(None, description="Diameter refined from the data, m")
    radius_um: list[float | None] = Field(description="Radius deviation per order 1..n, µm")
    accel_amp: list[float | None] = Field(description="Acceleration amplitude per order, m/s²")
    peak_to_peak_um: float | None = Field(None, description="Peak-to-peak of r(θ), µm")


class WheelTrend(BaseModel):
    """Wheel OOR of a vehicle over its runs, oldest first."""

    vehicle_id: str
    orders: list[int]
    items: list[WheelTrendPoint]
