"""Wheel out-of-roundness as the API answers it: a run's wheels, a vehicle's wheels over its runs, and
the wheel flats of a vehicle now.

The pipeline stores a wheel flat with the wheel's results (``wheel_oor.extra["flat"]``,
:func:`app.pipeline.impacts.flat_result`). A flat stays until the wheel is re-profiled, so it is
"first seen" in the earliest run of the unbroken series of the vehicle's runs, up to the one in
question, in which that wheel had a flat (:func:`flat_first_seen`).
"""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session

from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.core.jsonable import finite_or_none
from app.db import crud, results_reader
from app.db.models import Run, WheelOOR
from app.db.session import Database
from app.db.trends import wheel_history

__all__ = ["run_wheels", "wheel_trend", "vehicle_flats", "flat_of", "flat_first_seen"]

#: Runs of a vehicle looked back through for the first sighting of a flat.
_FLAT_HISTORY = 500

_FLAT_NUMBERS = ("angle_deg", "angle_spread_deg", "depth_mm", "length_mm", "first_km", "last_km")


def run_wheels(db: Database, run_id: int) -> dict[str, Any]:
    """Per wheel of a run: each OOR order as radius deviation (µm) with phase, r(θ) on 360 angles, and
    a wheel flat if one was found (position on the circumference, depth, the run it was first seen
    in); 404 without the run, 409 without results."""
    with db.read() as session:
        run = crud.get_run(session, run_id)
        if run is None:
            raise not_found("run", run_id)
        rows = results_reader.get_wheels(session, run_id)
        if not rows:
            latest = crud.latest_job(session, run_id)
            state = f"latest job {latest.id} is {latest.status}" if latest else "no job"
            raise ApiError(409, "wheels", _("run {run_id} has no results yet ({state})", run_id=run_id, state=state))
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
                "flat": _flat_answer(row, flat_first_seen(session, run, row.wheel)),
            }
            for row in rows
        ]
    return {"run_id": run_id, "items": items}


def wheel_trend(db: Database, vehicle_id: str, wheel: str | None, limit: int) -> dict[str, Any]:
    """Radius deviation (µm) and acceleration amplitude (m/s²) per OOR order, the peak-to-peak
    of r(θ) and the depth of a wheel flat (mm) for every wheel in every processed run of a vehicle,
    oldest run first."""
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
                "flat_depth_mm": finite_or_none((flat_of(oor) or {}).get("depth_mm")),
            })
    return {"vehicle_id": vehicle_id, "orders": list(range(1, n_orders + 1)), "items": items}


def vehicle_flats(db: Database, vehicle_id: str) -> dict[str, Any]:
    """Every wheel of the vehicle with a flat in its latest processed run: that run, where on the
    circumference, how deep, and the run it was first seen in; wheels ascending."""
    with db.read() as session:
        history = wheel_history(session, vehicle_id, None, _FLAT_HISTORY)
        latest: dict[str, int] = {}
        for i, (_run, oor) in enumerate(history):
            latest[oor.wheel] = i
        items = []
        for wheel in sorted(latest):
            run, oor = history[latest[wheel]]
            if flat_of(oor) is None:
                continue
            first = run
            for r, o in reversed([h for h in history[: latest[wheel]] if h[1].wheel == wheel]):
                if flat_of(o) is None:
                    break
                first = r
            items.append({"wheel": oor.wheel, "run_id": run.id, "start_time": run.start_time,
                          "flat": _flat_answer(oor, first)})
    return {"vehicle_id": vehicle_id, "items": items}


def flat_of(oor: WheelOOR) -> dict[str, Any] | None:
    """The wheel flat stored with a wheel's results, or None."""
    flat = (oor.extra or {}).get("flat")
    return flat if isinstance(flat, dict) else None


def flat_first_seen(session: Session, run: Run, wheel: str) -> Run | None:
    """The run in which the flat that ``wheel`` has in ``run`` was first seen (None: no flat there).

    Walks back from ``run`` through the vehicle's earlier processed runs while the wheel had a
    flat in them.
    """
    history = wheel_history(session, run.vehicle_id, wheel, _FLAT_HISTORY) if run.vehicle_id else []
    at = next((i for i, (r, _) in enumerate(history) if r.id == run.id), None)
    if at is None or flat_of(history[at][1]) is None:
        return None
    first = history[at][0]
    for r, oor in reversed(history[:at]):
        if flat_of(oor) is None:
            break
        first = r
    return first


def _flat_answer(oor: WheelOOR, first_seen: Run | None) -> dict[str, Any] | None:
    """The wheel flat of a wheel row as the API gives it (None: no flat)."""
    flat = flat_of(oor)
    if flat is None:
        return None
    return {
        **{k: finite_or_none(flat.get(k)) for k in _FLAT_NUMBERS},
        "n_hits": int(flat.get("n_hits") or 0),
        "n_revolutions": flat.get("n_revolutions"),
        "first_seen_run_id": first_seen.id if first_seen is not None else None,
        "first_seen_time": first_seen.start_time if first_seen is not None else None,
    }
