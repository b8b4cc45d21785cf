"""Schemas of wheel out-of-roundness results."""

from __future__ import annotations

import datetime as dt

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["WheelOrderOut", "WheelFlatOut", "WheelOut", "WheelList", "WheelTrendPoint", "WheelTrend",
           "VehicleFlat", "VehicleFlats"]


class WheelOrderOut(BaseModel):
    """One OOR order of a wheel."""

    model_config = ConfigDict(extra="allow")

    order: int
    radius_um: float | None = Field(None, description="Radius deviation amplitude, µm")
    radius_um_p05: float | None = Field(None, description="5th percentile over windows, µm")
    radius_um_p95: float | None = Field(None, description="95th percentile over windows, µm")
    phase_rad: float | None = Field(None, description="Phase referred to wheel angle, rad")
    accel_amp: float | None = Field(None, description="Acceleration amplitude, m/s²")


class WheelFlatOut(BaseModel):
    """A wheel flat: a dip of the tread met once per revolution (found from the periodic impacts)."""

    angle_deg: float = Field(description="Position on the circumference: the wheel angle θ = 2 s / d of its "
                             "centre (the convention of angles_deg and the OOR phases), degrees")
    angle_spread_deg: float | None = Field(None, description="Spread of the hits' angles, degrees")
    depth_mm: float = Field(description="Estimated depth, mm")
    length_mm: float | None = Field(None, description="Length of the best matched dip, mm")
    n_hits: int = Field(description="Impacts found one circumference apart")
    n_revolutions: int | None = Field(None, description="Revolutions between the first and the last hit")
    first_km: float | None = Field(None, description="Track position of the first hit in this run, km")
    last_km: float | None = Field(None, description="Track position of the last hit in this run, km")
    first_seen_run_id: int | None = Field(None, description="Run of the vehicle in which it was first seen "
                                          "(earliest of the unbroken series of runs with a flat on this wheel)")
    first_seen_time: dt.datetime | None = Field(None, description="Start time of that run")


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
    flat: WheelFlatOut | None = Field(None, description="A wheel flat found in this run, if any")


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
    flat_depth_mm: float | None = Field(None, description="Depth of a wheel flat found in this run, mm")


class WheelTrend(BaseModel):
    """Wheel OOR of a vehicle over its runs, oldest first."""

    vehicle_id: str
    orders: list[int]
    items: list[WheelTrendPoint]


class VehicleFlat(BaseModel):
    """A wheel of a vehicle with a flat in its latest processed run."""

    wheel: str
    run_id: int = Field(description="The wheel's latest processed run")
    start_time: dt.datetime | None = None
    flat: WheelFlatOut


class VehicleFlats(BaseModel):
    """The wheel flats of a vehicle now (its wheels' latest runs)."""

    vehicle_id: str
    items: list[VehicleFlat]
