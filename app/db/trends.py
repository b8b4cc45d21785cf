"""Queries across runs: wheel out-of-roundness of a vehicle over time."""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session

from app.db.models import Run, WheelOOR

__all__ = ["wheel_history"]


def wheel_history(
    session: Session, vehicle_id: str, wheel: str | None = None, limit: int = 500
) -> list[tuple[Run, WheelOOR]]:
    """Wheel results of every processed run of a vehicle, oldest run first.

    Parameters
    ----------
    vehicle_id : str
        Vehicle id (exact match).
    wheel : str, optional
        One wheel (``"11"`` …); all wheels when omitted.
    limit : int
        Most recent runs kept (> 0).

    Returns
    -------
    list of (Run, WheelOOR)
        Ordered by run start time (runs without a start time last), then run id and wheel.
    """
    if limit < 1:
        raise ValueError(f"limit must be >= 1, got {limit}")
    run_ids = (
        select(Run.id)
        .where(Run.vehicle_id == vehicle_id)
        .order_by(Run.start_time.desc(), Run.id.desc())
        .limit(limit)
        .scalar_subquery()
    )
    query = select(Run, WheelOOR).join(WheelOOR, WheelOOR.run_id == Run.id).where(Run.id.in_(run_ids))
    if wheel is not None:
        query = query.where(WheelOOR.wheel == wheel)
    rows = session.execute(query).all()
    rows.sort(key=lambda r: (r[0].start_time is None, r[0].start_time or r[0].created_at, r[0].id, r[1].wheel))
    return [(run, oor) for run, oor in rows]
