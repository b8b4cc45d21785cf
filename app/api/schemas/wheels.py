"""Schemas of wheel out-of-roundness results."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["WheelOrderOut", "WheelOut", "WheelList"]


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
