"""Wheel out-of-roundness results of a run."""

from __future__ import annotations

import math
from typing import Annotated, Any

from fastapi import APIRouter, Query

from app.api.deps import DbDep, RunId
from app.api.errors import ApiError, not_found
from app.api.schemas.wheels import (
    VehicleFlat,
    VehicleFlats,
    WheelFlatOut,
    WheelList,
    WheelOrderOut,
    WheelOut,
    WheelTrend,
    WheelTrendPoint,
)
from app.db import crud, results_reader
from app.db.models import Run
from app.db.trends import wheel_history
from app.db.wheel_flats import flat_first_seen, flat_of, vehicle_flats

__all__ = ["router"]

router = APIRouter(tags=["wheels"])


@router.get(
    "/runs/{run_id}/wheels",
    response_model=WheelList,
    summary="Wheel OOR of a run",
    responses={409: {"description": "The run has no results yet"}},
)
def get_wheels(run_id: RunId, db: DbDep) -> WheelList:
    """Per wheel: each OOR order as radius deviation (µm) with phase, r(θ) on 360 angles, and a wheel
    flat if one was found (position on the circumference, depth, the run it was first seen in)."""
    with db.read() as session:
        run = crud.get_run(session, run_id)
        if run is None:
            raise not_found("run", run_id)
        rows = results_reader.get_wheels(session, run_id)
        if not rows:
            latest = crud.latest_job(session, run_id)
            state = f"latest job {latest.id} is {latest.status}" if latest else "no job"
            raise ApiError(409, "wheels", f"run {run_id} has no results yet ({state})")
        items = [
            WheelOut(
                wheel=row.wheel,
                job_id=row.job_id,
                wheel_diameter_m=row.wheel_diameter_m,
                n_windows=row.n_windows,
                orders=[WheelOrderOut(**o) for o in (row.orders or [])],
                angles_deg=list(row.angles_deg or []),
                profile_um=list(row.profile_um or []),
                profile_p05_um=row.profile_p05_um,
                profile_p95_um=row.profile_p95_um,
                flat=_flat_out(row, flat_first_seen(session, run, row.wheel)),
            )
            for row in rows
        ]
    return WheelList(run_id=run_id, items=items)


def _flat_out(row: Any, first_seen: Run | None) -> WheelFlatOut | None:
    """The wheel flat of a wheel row as the API gives it (None: no flat)."""
    flat = flat_of(row)
    if flat is None:
        return None
    return WheelFlatOut(
        **{k: _num(flat.get(k)) for k in ("angle_deg", "angle_spread_deg", "depth_mm", "length_mm", "first_km",
                                           "last_km")},
        n_hits=int(flat.get("n_hits") or 0), n_revolutions=flat.get("n_revolutions"),
        first_seen_run_id=first_seen.id if first_seen is not None else None,
        first_seen_time=first_seen.start_time if first_seen is not None else None,
    )


def _num(value: Any) -> float | None:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


@router.get("/wheels/trend", response_model=WheelTrend, summary="Wheel OOR of a vehicle over its runs")
def wheel_trend(
    db: DbDep,
    vehicle_id: Annotated[str, Query(min_length=1, max_length=200, description="Vehicle id")],
    wheel: Annotated[
        str | None, Query(pattern=r"^(11|12|41|42)$", description="One wheel; all when omitted")
    ] = None,
    limit: Annotated[int, Query(ge=1, le=500, description="Most recent runs")] = 200,
) -> WheelTrend:
    """Radius deviation (µm) and acceleration amplitude (m/s²) per OOR order and the
    peak-to-peak of r(θ) for every wheel in every processed run of a vehicle, oldest
    run first: the trend of the wheels' out-of-roundness between re-profilings."""
    with db.read() as session:
        rows = wheel_history(session, vehicle_id, wheel, limit)
        items = []
        n_orders = 0
        for run, oor in rows:
            orders = sorted(oor.orders or [], key=lambda o: int(o.get("order", 0)))
            n_orders = max(n_orders, len(orders))
            profile = [v for v in (_num(x) for x in (oor.profile_um or [])) if v is not None]
            items.append(
                WheelTrendPoint(
                    run_id=run.id,
                    start_time=run.start_time,
                    line_id=run.line_id,
                    track=run.track,
                    wheel=oor.wheel,
                    wheel_diameter_m=_num(oor.wheel_diameter_m),
                    refined_diameter_m=_num((oor.extra or {}).get("refined_diameter_m")),
                    radius_um=[_num(o.get("radius_um")) for o in orders],
                    accel_amp=[_num(o.get("accel_amp")) for o in orders],
                    peak_to_peak_um=(max(profile) - min(profile)) if profile else None,
                    flat_depth_mm=_num((flat_of(oor) or {}).get("depth_mm")),
                )
            )
    return WheelTrend(vehicle_id=vehicle_id, orders=list(range(1, n_orders + 1)), items=items)


@router.get("/wheels/flats", response_model=VehicleFlats, summary="Wheel flats of a vehicle now")
def wheel_flats(
    db: DbDep,
    vehicle_id: Annotated[str, Query(min_length=1, max_length=200, description="Vehicle id")],
) -> VehicleFlats:
    """Every wheel of the vehicle that has a flat in its latest processed run: where on the
    circumference, how deep, and the run it was first seen in."""
    with db.read() as session:
        items = [
            VehicleFlat(wheel=oor.wheel, run_id=run.id, start_time=run.start_time,
                        flat=_flat_out(oor, first))  # type: ignore[arg-type]
            for run, oor, first in vehicle_flats(session, vehicle_id)
        ]
    return VehicleFlats(vehicle_id=vehicle_id, items=items)
