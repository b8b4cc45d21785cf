"""Schemas of a run's track impacts."""

from __future__ import annotations

from pydantic import BaseModel, Field

__all__ = ["TrackImpactOut", "TrackImpactList"]


class TrackImpactOut(BaseModel):
    """An isolated impact fixed to the track (a dipped weld or joint)."""

    km: float = Field(description="Position, km")
    depth_mm: float = Field(description="Estimated depth of the dip, mm (mean over the wheels)")
    depth_by_side_mm: dict[str, float] = Field(description="Mean depth per rail side (1 right, 2 left), mm")
    wheels: list[str] = Field(description="Wheels that met it")


class TrackImpactList(BaseModel):
    """The track impacts of a run's results (the sleeper indicator is bridged around each)."""

    run_id: int
    job_id: int | None = Field(None, description="Job whose results these are (null: none yet)")
    items: list[TrackImpactOut]
