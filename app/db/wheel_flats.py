"""Wheel flats found in a vehicle's runs, and when each was first seen.

The pipeline stores a wheel flat with the wheel's results
(``wheel_oor.extra["flat"]``, :func:`app.pipeline.impacts.flat_result`). A
flat stays until the wheel is re-profiled, so it is "first seen" in the
earliest run of the unbroken series of the vehicle's runs, up to the one in
question, in which that wheel had a flat (:func:`flat_first_seen`).
"""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session

from app.db.models import Run, WheelOOR
from app.db.trends import wheel_history

__all__ = ["flat_of", "flat_first_seen", "vehicle_flats"]

#: Runs of a vehicle looked back through for the first sighting of a flat.
_HISTORY = 500


def flat_of(oor: WheelOOR) -> dict[str, Any] | None:
    """The wheel flat stored with a wheel's results, or None."""
    flat = (oor.extra or {}).get("flat")
    return flat if isinstance(flat, dict) else None


def flat_first_seen(session: Session, run: Run, wheel: str) -> Run | None:
    """The run in which the flat that ``wheel`` has in ``run`` was first seen (None: no flat there).

    Walks back from ``run`` through the vehicle's earlier processed runs while
    the wheel had a flat in them.
    """
    history = wheel_history(session, run.vehicle_id, wheel, _HISTORY) if run.vehicle_id else []
    at = next((i for i, (r, _) in enumerate(history) if r.id == run.id), None)
    if at is None or flat_of(history[at][1]) is None:
        return None
    first = history[at][0]
    for r, oor in reversed(history[:at]):
        if flat_of(oor) is None:
            break
        first = r
    return first


def vehicle_flats(session: Session, vehicle_id: str) -> list[tuple[Run, WheelOOR, Run]]:
    """Per wheel of a vehicle with a flat in its latest processed run: (that run, its wheel row, first seen run)."""
    history = wheel_history(session, vehicle_id, None, _HISTORY)
    latest: dict[str, int] = {}
    for i, (_, oor) in enumerate(history):
        latest[oor.wheel] = i
    out = []
    for wheel in sorted(latest):
        run, oor = history[latest[wheel]]
        if flat_of(oor) is None:
            continue
        first = run
        for r, o in reversed([h for h in history[: latest[wheel]] if h[1].wheel == wheel]):
            if flat_of(o) is None:
                break
            first = r
        out.append((run, oor, first))
    return out
