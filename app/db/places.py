"""Plain queries of the places' tables (:mod:`app.db.models.places`): reads for the lifecycle and the
work list, the store's 10 m segment rows the places are found on. No decisions here
(:mod:`app.places` makes them)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence

import numpy as np
from sqlalchemy import and_, delete, func, select, text
from sqlalchemy.orm import Session

from app.db.models import (
    ConditionRun,
    Place,
    PlaceAction,
    PlaceEventRow,
    PlaceObservation,
    PlaceRun,
    PlaceStatusChange,
    Run,
    SegmentCondition,
)

__all__ = [
    "lock_places",
    "applied_run",
    "latest_applied_time",
    "history_runs",
    "segment_frame",
    "run_time",
    "run_vehicles",
    "line_places",
    "observations_of",
    "latest_speeds",
    "actions_of",
    "events_of",
    "status_history_of",
    "delete_places",
    "next_place_id",
]

#: advisory lock key of the places (PostgreSQL): one line's places are advanced by one run at a time
_PLACES_LOCK = 0x7476_6B66_25


def lock_places(session: Session) -> None:
    """Serialise the places' updates (PostgreSQL: transaction-level advisory lock; SQLite writes are serial)."""
    if session.get_bind().dialect.name == "postgresql":
        session.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": _PLACES_LOCK})


def applied_run(session: Session, run_id: int) -> PlaceRun | None:
    """The run's entry if it was applied to its line's places."""
    return session.get(PlaceRun, run_id)


def latest_applied_time(session: Session, line_key: int) -> dt.datetime | None:
    """Time of the newest run applied to the line's places."""
    return session.scalar(select(func.max(PlaceRun.run_time)).where(PlaceRun.line_key == line_key))


def history_runs(session: Session, line_key: int, when: dt.datetime, method_version: str, *,
                 scan_runs: int, window_days: float) -> list[tuple[int, dt.datetime]]:
    """Earlier runs applied to the line with this method version, oldest first: the ``scan_runs`` newest, and
    of the older ones within ``window_days`` before ``when`` at most ``scan_runs`` spread evenly over the
    window (daily runs would otherwise make the read grow with the window: a trend needs its span, not every
    run)."""
    base = and_(PlaceRun.line_key == line_key, PlaceRun.method_version == method_version, PlaceRun.run_time < when)
    newest = session.execute(select(PlaceRun.run_id, PlaceRun.run_time).where(base)
                             .order_by(PlaceRun.run_time.desc()).limit(scan_runs)).all()
    picked = {(int(r), t) for r, t in newest}
    if len(newest) == scan_runs:
        oldest = min(t for _, t in newest)
        window = session.execute(select(PlaceRun.run_id, PlaceRun.run_time).where(
            base, PlaceRun.run_time < oldest, PlaceRun.run_time >= when - dt.timedelta(days=window_days))
            .order_by(PlaceRun.run_time)).all()
        if len(window) > scan_runs:
            keep = np.unique(np.linspace(0, len(window) - 1, scan_runs).round().astype(int))
            window = [window[k] for k in keep]
        picked |= {(int(r), t) for r, t in window}
    return sorted(picked, key=lambda x: (x[1], x[0]))


def segment_frame(session: Session, run_ids: Sequence[int], seg_m: int = 10) -> tuple[np.ndarray, list[str]]:
    """The store's ``seg_m`` rows of the runs.

    Returns
    -------
    values : numpy.ndarray
        (n, 6) float64: run id, wheel code (index into ``wheels``), segment, ``ln A``, speed (m/s), the stated
        1-σ of ``ln A`` (``condition_index_sd``; NaN: none).
    wheels : list of str
        The wheel names.
    """
    if not run_ids:
        return np.zeros((0, 6)), []
    sc = SegmentCondition
    ids = [int(r) for r in run_ids]
    wheels = sorted(str(w) for w in session.scalars(select(sc.wheel).where(sc.run_id.in_(ids), sc.seg_m == int(seg_m))
                                                    .distinct()))
    parts = []
    for code, wheel in enumerate(wheels):
        # numeric columns only, through the driver's cursor: a year of a long line is millions of rows
        stmt = select(sc.run_id, sc.seg, sc.condition_index, sc.speed_mean, sc.condition_index_sd).where(
            sc.run_id.in_(ids), sc.seg_m == int(seg_m), sc.wheel == wheel)
        result = session.connection().execute(stmt)
        try:
            raw = result.cursor.fetchall()
        finally:
            result.close()
        a = np.array(raw, dtype=np.float64).reshape(len(raw), 5)  # NULL -> NaN
        parts.append(np.column_stack([a[:, 0], np.full(len(raw), float(code)), a[:, 1:]]))
    return (np.concatenate(parts) if parts else np.zeros((0, 6))), wheels


def run_time(session: Session, run_id: int) -> dt.datetime | None:
    """The run's time in the condition store."""
    return session.scalar(select(ConditionRun.run_time).where(ConditionRun.run_id == run_id))


def run_vehicles(session: Session, run_ids: Sequence[int]) -> dict[int, str | None]:
    """The vehicle of each run (None: not stated), by run id."""
    if not run_ids:
        return {}
    rows = session.execute(select(Run.id, Run.vehicle_id).where(Run.id.in_([int(r) for r in run_ids]))).all()
    return {int(r): (str(v) if v else None) for r, v in rows}


def line_places(session: Session, line_key: int) -> list[Place]:
    """Every place of the line (for the lifecycle), by id."""
    return list(session.scalars(select(Place).where(Place.line_key == line_key).order_by(Place.id)))


def observations_of(session: Session, place_ids: Sequence[int]) -> dict[int, list[PlaceObservation]]:
    """Observations of the places, oldest first, by place id."""
    out: dict[int, list[PlaceObservation]] = {int(i): [] for i in place_ids}
    if not out:
        return out
    rows = session.scalars(select(PlaceObservation).where(PlaceObservation.place_id.in_(list(out)))
                           .order_by(PlaceObservation.place_id, PlaceObservation.day, PlaceObservation.id))
    for r in rows:
        out[r.place_id].append(r)
    return out


def latest_speeds(session: Session, place_ids: Sequence[int]) -> dict[int, float]:
    """The speed of each place's latest observation (its last run), km/h, by place id (none: left out)."""
    ids = [int(i) for i in place_ids]
    if not ids:
        return {}
    rows = session.execute(select(PlaceObservation.place_id, PlaceObservation.speed_kmh)
                           .join(Place, and_(Place.id == PlaceObservation.place_id,
                                             Place.last_run_id == PlaceObservation.run_id))
                           .where(Place.id.in_(ids), PlaceObservation.speed_kmh.isnot(None)))
    return {int(a): float(b) for a, b in rows}


def actions_of(session: Session, place_ids: Sequence[int]) -> dict[int, list[PlaceAction]]:
    """Maintenance actions linked to the places, by place id (by date)."""
    out: dict[int, list[PlaceAction]] = {int(i): [] for i in place_ids}
    if not out:
        return out
    for r in session.scalars(select(PlaceAction).where(PlaceAction.place_id.in_(list(out)))
                             .order_by(PlaceAction.date, PlaceAction.action_id)):
        out[r.place_id].append(r)
    return out


def events_of(session: Session, place_id: int) -> list[PlaceEventRow]:
    """A place's events, oldest first."""
    return list(session.scalars(select(PlaceEventRow).where(PlaceEventRow.place_id == place_id)
                                .order_by(PlaceEventRow.id)))


def status_history_of(session: Session, place_id: int) -> list[PlaceStatusChange]:
    """A place's status changes, oldest first."""
    return list(session.scalars(select(PlaceStatusChange).where(PlaceStatusChange.place_id == place_id)
                                .order_by(PlaceStatusChange.id)))


def delete_places(session: Session, place_ids: Sequence[int]) -> None:
    """Delete places with their rows (candidates the lifecycle forgot)."""
    ids = [int(i) for i in place_ids]
    if not ids:
        return
    for table in (PlaceObservation, PlaceEventRow, PlaceStatusChange, PlaceAction):
        session.execute(delete(table).where(table.place_id.in_(ids)))
    session.execute(delete(Place).where(Place.id.in_(ids)))


def next_place_id(session: Session) -> int:
    """The id the next new place gets (under :func:`lock_places`)."""
    return int(session.scalar(select(func.coalesce(func.max(Place.id), 0))) or 0) + 1
