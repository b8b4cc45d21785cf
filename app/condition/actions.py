"""The line's recorded maintenance actions on the time axis of the change tests.

The condition store (:mod:`app.condition.writer`), the places (:mod:`app.places`) and the synthetic fleet
read a day as days since 1970-01-01 UTC (:func:`days_of`) and the line's actions by what they act on:
the rails' surface (grinding, rail renewal) or the support (every other type), as ``(start_m, end_m,
day)`` arrays. Kept apart from the writer so that the API's readers do not load the processing engine.
"""

from __future__ import annotations

import datetime as dt

import numpy as np
from sqlalchemy.orm import Session

from app.analysis.condition.interventions import RAIL_SURFACE_ACTIONS
from app.db import reference_crud
from app.db.models import MAINTENANCE_TYPES

_EPOCH = dt.datetime(1970, 1, 1, tzinfo=dt.UTC)


def days_of(when: dt.datetime) -> float:
    """Days since 1970-01-01 UTC (the time axis of the change tests)."""
    return (when - _EPOCH).total_seconds() / 86400.0


def _interventions(session: Session, line_id: str, track: str,
                   types: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The line's imported maintenance actions of ``types`` as ``(start_m, end_m, day)`` arrays (m on the km
    axis, days since 1970)."""
    frame = reference_crud.reference_frame(session, "maintenance", line_id=line_id, track=track, types=types)
    if frame.empty:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    day = np.array([days_of(dt.datetime.combine(d, dt.time(), tzinfo=dt.UTC)) for d in frame["date"]])
    return (frame["km_from"].to_numpy(dtype=np.float64) * 1000.0, frame["km_to"].to_numpy(dtype=np.float64) * 1000.0,
            day)


def rail_surface_interventions(session: Session, line_id: str, track: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The line's imported maintenance actions that change the rails' surface (grinding, rail renewal:
    :data:`~app.analysis.condition.interventions.RAIL_SURFACE_ACTIONS`) as ``(start_m, end_m, day)`` arrays
    (m on the km axis, days since 1970)."""
    return _interventions(session, line_id, track, list(RAIL_SURFACE_ACTIONS))


def support_interventions(session: Session, line_id: str, track: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The line's imported maintenance actions on the support — every type that is not on the rails' surface
    (tamping, ballast cleaning, other) — as ``(start_m, end_m, day)`` arrays: a segment's history starts anew
    after the latest one over it (:func:`~app.analysis.condition.interventions.since_actions`)."""
    return _interventions(session, line_id, track, [t for t in MAINTENANCE_TYPES if t not in RAIL_SURFACE_ACTIONS])
