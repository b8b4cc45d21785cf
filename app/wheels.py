"""Wheel out-of-roundness as the API answers it: a run's wheels, and a vehicle's wheels over its runs."""

from __future__ import annotations

from typing import Any

from app.core.errors import ApiError, not_found
from app.core.jsonable import finite_or_none
from app.db import crud, results_reader
from app.db.session import Database
from app.db.trends import wheel_history

__all__ = ["run_wheels", "wheel_trend"]


def run_wheels(db: Database, run_id: int) -> dict[str, Any]:
    """Per wheel of a run: each OOR order as radius deviation (µm) with phase, and r(θ) on 360 angles;
    404 without the run, 409 without results."""
    with db.read() as session:
        if crud.get_run(session, run_id) is None:
            raise not_found("run", run_id)
        rows = results_reader.get_wheels(session, run_id)
        if not rows:
            latest = crud.latest_job(session, run_id)
            state = f"latest job {latest.id} is {latest.status}" if latest else "no job"
            raise ApiError(409, "wheels", f"run {run_id} has no results yet ({state})")
        items = [
            {
                "wheel": row.wheel,
                "job_id": row.job_id,
                "wheel_diameter_m": row.wheel_diameter_m,
                "n_windows": row.n_windows,
                "orders": list(row.orders or []),
                "angles_deg": list(row.angles_deg or []),
                "profile_um": list(row.profile_um or []),
                "profile_p05_um": row.profile_p05_um,
                "profile_p95_um": row.profile_p95_um,
            }
            for row in rows
        ]
    return {"run_id": run_id, "items": items}


def wheel_trend(db: Database, vehicle_id: str, wheel: str | None, limit: int) -> dict[str, Any]:
    """Radius deviation (µm) and acceleration amplitude (m/s²) per OOR order and the peak-to-peak
    of r(θ) for every wheel in every processed run of a vehicle, oldest run first."""
    with db.read() as session:
        rows = wheel_history(session, vehicle_id, wheel, limit)
        items = []
        n_orders = 0
        for run, oor in rows:
            orders = sorted(oor.orders or [], key=lambda o: int(o.get("order", 0)))
            n_orders = max(n_orders, len(orders))
            profile = [v for v in (finite_or_none(x) for x in (oor.profile_um or [])) if v is not None]
            items.append({
                "run_id": run.id,
                "start_time": run.start_time,
                "line_id": run.line_id,
                "track": run.track,
                "wheel": oor.wheel,
                "wheel_diameter_m": finite_or_none(oor.wheel_diameter_m),
                "refined_diameter_m": finite_or_none((oor.extra or {}).get("refined_diameter_m")),
                "radius_um": [finite_or_none(o.get("radius_um")) for o in orders],
                "accel_amp": [finite_or_none(o.get("accel_amp")) for o in orders],
                "peak_to_peak_um": (max(profile) - min(profile)) if profile else None,
            })
    return {"vehicle_id": vehicle_id, "orders": list(range(1, n_orders + 1)), "items": items}
