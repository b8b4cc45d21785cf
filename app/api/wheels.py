"""Wheel out-of-roundness results of a run, of a vehicle over its runs, and a vehicle's wheel flats:
the routes (:mod:`app.wheels`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from app.api.deps import DbDep, RunId, WheelQ, wheel_param
from app.api.schemas.wheels import VehicleFlats, WheelList, WheelTrend
from app.wheels import run_wheels, vehicle_flats
from app.wheels import wheel_trend as vehicle_wheel_trend

__all__ = ["router"]

router = APIRouter(tags=["wheels"])

VehicleQ = Annotated[str, Query(min_length=1, max_length=200, description="Vehicle id")]


@router.get(
    "/runs/{run_id}/wheels",
    response_model=WheelList,
    summary="Wheel OOR of a run",
    responses={409: {"description": "The run has no results yet"}},
)
def get_wheels(run_id: RunId, db: DbDep) -> WheelList:
    """Per wheel: each OOR order as radius deviation (µm) with phase, r(θ) on 360 angles, and a wheel
    flat if one was found (position on the circumference, depth, the run it was first seen in)."""
    return WheelList(**run_wheels(db, run_id))


@router.get("/wheels/trend", response_model=WheelTrend, summary="Wheel OOR of a vehicle over its runs")
def wheel_trend(
    db: DbDep,
    vehicle_id: VehicleQ,
    wheel: WheelQ = None,
    limit: Annotated[int, Query(ge=1, le=500, description="Most recent runs")] = 200,
) -> WheelTrend:
    """Radius deviation (µm) and acceleration amplitude (m/s²) per OOR order and the
    peak-to-peak of r(θ) for every wheel in every processed run of a vehicle, oldest
    run first: the trend of the wheels' out-of-roundness between re-profilings."""
    return WheelTrend(**vehicle_wheel_trend(db, vehicle_id, wheel_param(wheel), limit))


@router.get("/wheels/flats", response_model=VehicleFlats, summary="Wheel flats of a vehicle now")
def wheel_flats(db: DbDep, vehicle_id: VehicleQ) -> VehicleFlats:
    """Every wheel of the vehicle that has a flat in its latest processed run: where on the
    circumference, how deep, and the run it was first seen in."""
    return VehicleFlats(**vehicle_flats(db, vehicle_id))
