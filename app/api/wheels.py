"""Wheel out-of-roundness results of a run, and of a vehicle over its runs: the routes (:mod:`app.wheels`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from app.api.deps import DbDep, RunId, WheelQ, wheel_param
from app.api.schemas.wheels import WheelList, WheelTrend
from app.wheels import run_wheels
from app.wheels import wheel_trend as vehicle_wheel_trend

__all__ = ["router"]

router = APIRouter(tags=["wheels"])


@router.get(
    "/runs/{run_id}/wheels",
    response_model=WheelList,
    summary="Wheel OOR of a run",
    responses={409: {"description": "The run has no results yet"}},
)
def get_wheels(run_id: RunId, db: DbDep) -> WheelList:
    """Per wheel: each OOR order as radius deviation (µm) with phase, and r(θ) on 360 angles."""
    return WheelList(**run_wheels(db, run_id))


@router.get("/wheels/trend", response_model=WheelTrend, summary="Wheel OOR of a vehicle over its runs")
def wheel_trend(
    db: DbDep,
    vehicle_id: Annotated[str, Query(min_length=1, max_length=200, description="Vehicle id")],
    wheel: WheelQ = None,
    limit: Annotated[int, Query(ge=1, le=500, description="Most recent runs")] = 200,
) -> WheelTrend:
    """Radius deviation (µm) and acceleration amplitude (m/s²) per OOR order and the
    peak-to-peak of r(θ) for every wheel in every processed run of a vehicle, oldest
    run first: the trend of the wheels' out-of-roundness between re-profilings."""
    return WheelTrend(**vehicle_wheel_trend(db, vehicle_id, wheel_param(wheel), limit))
