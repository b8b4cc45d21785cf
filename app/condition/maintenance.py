"""What maintenance did: the condition index over a stretch of line, per run and along km, relative
to its surroundings, and the effect of every imported action (:func:`action_effects`).

Values are *relative to the surrounding track of the same run*: the index over
the stretch minus the run's mean over the ``NEIGHBOURHOOD_KM`` either side
(the stretch and ``GAP_KM`` either side left out; from the runs' 100 m overview
rows). What the whole neighbourhood shares in one run — the speed the train
passed at (the condition index, ln A, is not speed-conditioned), a sensor's
calibration, the season — cancels, and what happened to the stretch remains.
The rows are read run by run through the primary keys (a stretch of a year of
daily runs: a few thousand rows).
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.analysis.condition.maintenance_effect import ActionEffect, action_effect
from app.condition.lines import check_line_km, resolve_line
from app.condition.readers import OVERVIEW_M, line_runs
from app.condition.writer import days_of
from app.core.errors import ApiError, not_found
from app.db import reference_crud
from app.db.models import (
    ConditionLine,
    ConditionOverview,
    ConditionRun,
    MaintenanceAction,
    SegmentCondition,
)
from app.db.numeric import fetch_numeric
from app.db.session import Database
from app.io import WHEELS

__all__ = ["NEIGHBOURHOOD_KM", "GAP_KM", "extent_segments", "run_levels", "extent_series", "extent_profile",
           "action_effects", "action_effect_detail"]

#: Surroundings of a stretch each run's level is taken from, km either side.
NEIGHBOURHOOD_KM = 1.0
#: Left out between the stretch and its surroundings, km either side.
GAP_KM = 0.05


def extent_segments(km_from: float, km_to: float, seg_m: int) -> tuple[int, int]:
    """First and last segment whose centre lies in ``[km_from, km_to]`` (for a stretch shorter than
    a segment: the segment holding its middle)."""
    lo, hi = sorted((km_from, km_to))
    a, b = math.ceil(lo * 1000.0 / seg_m - 0.5), math.floor(hi * 1000.0 / seg_m - 0.5)
    if b < a:
        a = b = math.floor((lo + hi) / 2 * 1000.0 / seg_m)
    return a, b


def run_levels(session: Session, runs: list[int], km_from: float, km_to: float) -> dict[int, float]:
    """Per run the mean index (over the wheels) of the surroundings of ``[km_from, km_to]``."""
    lo, hi = sorted((km_from, km_to))
    a, b = math.floor((lo - NEIGHBOURHOOD_KM) * 1000.0 / OVERVIEW_M), math.floor((hi + NEIGHBOURHOOD_KM) * 1000.0 / OVERVIEW_M)
    ea, eb = math.floor((lo - GAP_KM) * 1000.0 / OVERVIEW_M), math.floor((hi + GAP_KM) * 1000.0 / OVERVIEW_M)
    if not runs:
        return {}
    o = ConditionOverview
    values = fetch_numeric(session, select(o.run_id, func.avg(o.condition_index)).where(
        o.run_id.in_(runs), o.seg >= a, o.seg <= b, (o.seg < ea) | (o.seg > eb)).group_by(o.run_id), 2)
    return dict(zip(values[:, 0].astype(int).tolist(), values[:, 1].tolist(), strict=True))


def _wheel_rows(session: Session, runs: list[int], seg_m: int, a: int, b: int, *, by_seg: bool) -> np.ndarray:
    """``(run_id, [seg,] mean index over the wheels)`` of segments a…b of the runs (primary-key ranges)."""
    sc = SegmentCondition
    keys = (sc.run_id, sc.seg) if by_seg else (sc.run_id,)
    stmt = select(*keys, func.avg(sc.condition_index)).where(
        sc.run_id.in_(runs), sc.seg_m == seg_m, sc.wheel.in_(list(WHEELS)), sc.seg >= a, sc.seg <= b).group_by(*keys)
    return fetch_numeric(session, stmt, len(keys) + 1)


def extent_series(session: Session, line: ConditionLine, km_from: float, km_to: float,
                  seg_m: int = 10) -> tuple[list[ConditionRun], np.ndarray]:
    """The line's runs holding the stretch (oldest first) and its index relative to the surroundings."""
    runs = line_runs(session, line.id)
    ids = [r.run_id for r in runs]
    if not ids:
        return [], np.zeros(0)
    a, b = extent_segments(km_from, km_to, seg_m)
    values = _wheel_rows(session, ids, seg_m, a, b, by_seg=False)
    levels = run_levels(session, ids, km_from, km_to)
    mean = {int(r): v - levels[int(r)] for r, v in values if int(r) in levels}
    runs = [r for r in runs if r.run_id in mean]
    return runs, np.array([mean[r.run_id] for r in runs])


def extent_profile(session: Session, run_ids: list[int], km_from: float, km_to: float, *,
                   action_km: tuple[float, float], seg_m: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Segment starts (km) over ``[km_from, km_to]`` and the mean over ``run_ids`` of each segment's index
    relative to the run's surroundings of ``action_km``."""
    if not run_ids:
        return np.zeros(0), np.zeros(0)
    levels = run_levels(session, run_ids, *action_km)
    a, b = math.floor(min(km_from, km_to) * 1000.0 / seg_m), math.floor(max(km_from, km_to) * 1000.0 / seg_m)
    values = _wheel_rows(session, run_ids, seg_m, a, b, by_seg=True)
    values = values[np.array([int(r) in levels for r in values[:, 0]], dtype=bool)] if len(values) else values
    if not len(values):
        return np.zeros(0), np.zeros(0)
    rel = values[:, 2] - np.array([levels[int(r)] for r in values[:, 0]])
    segs, inverse = np.unique(values[:, 1].astype(np.int64), return_inverse=True)
    mean = np.bincount(inverse, weights=rel) / np.bincount(inverse)
    return segs * seg_m / 1000.0, mean

# --- the answers of /condition/maintenance-effect ------------------------------------------------
#: Margin of the before/after profile around an action's extent, km.
MARGIN_KM = 0.1


def _effect_of(db: Database, line: ConditionLine, a: MaintenanceAction, *, before_days: float, after_days: float,
               regain: float) -> tuple[ActionEffect, list, np.ndarray]:
    with db.read() as session:
        runs, values = extent_series(session, line, a.km_from, a.km_to)
    day = days_of(dt.datetime.combine(a.date, dt.time(12, 0), tzinfo=dt.UTC))
    days = np.array([days_of(r.run_time) for r in runs])
    effect = action_effect(days, values, day, before_days=before_days, after_days=after_days,
                           regain_fraction=regain)
    return effect, runs, values


def _out(a: MaintenanceAction, line: ConditionLine, e: ActionEffect, n_runs: int) -> dict:
    return {
        "action_id": a.id, "line_id": line.line_id, "track": line.track, "type": a.type, "date": a.date.isoformat(),
        "km_from": a.km_from, "km_to": a.km_to, "n_runs": n_runs, "n_runs_before": e.n_before, "n_runs_after": e.n_after,
        "condition_index_before": e.index_before, "condition_index_after": e.index_after, "recovery": e.recovery,
        "recovery_pct": 100.0 * math.expm1(e.recovery) if e.recovery is not None else None,
        "slope_after_per_year": e.slope_after_per_year, "lasted_days_observed": e.lasted_days_observed,
        "lasted_days_projected": e.lasted_days_projected,
    }


def action_effects(db: Database, line_id: str, track: str | None, *, types: list[str] | None,
                   since: dt.date | None, km_from: float | None, km_to: float | None, before_days: float,
                   after_days: float, regain_fraction: float) -> dict:
    """Every imported action of the line (filtered by type, date, km): the index over its extent
    before and after, the recovery, the slope after and how long the recovery lasted."""
    line = resolve_line(db, line_id, track)
    check_line_km(line, km_from=km_from, km_to=km_to)
    with db.read() as session:
        actions = reference_crud.reference_frame(session, "maintenance", line_id=line.line_id, track=line.track,
                                                 km_from=km_from, km_to=km_to, types=types, since=since)
        rows = [session.get(MaintenanceAction, int(i)) for i in actions["id"]]
    items = []
    for a in sorted(rows, key=lambda r: (r.date, r.km_from)):
        effect, runs, _ = _effect_of(db, line, a, before_days=before_days, after_days=after_days,
                                     regain=regain_fraction)
        items.append(_out(a, line, effect, len(runs)))
    return {"regain_fraction": regain_fraction, "items": items}


def action_effect_detail(db: Database, action_id: int, *, before_days: float, after_days: float,
                         regain_fraction: float) -> dict:
    """The action's effect, the index over its extent per run, and the index along km (extent
    ± :data:`MARGIN_KM`) averaged over the runs before and the runs just after."""
    with db.read() as session:
        a = session.get(MaintenanceAction, action_id)
    if a is None:
        raise not_found("action", action_id)
    line = resolve_line(db, a.line_id, a.track)
    effect, runs, values = _effect_of(db, line, a, before_days=before_days, after_days=after_days,
                                      regain=regain_fraction)
    day = days_of(dt.datetime.combine(a.date, dt.time(12, 0), tzinfo=dt.UTC))
    days = np.array([days_of(r.run_time) for r in runs])
    before = [r.run_id for r, d in zip(runs, days, strict=True) if day - before_days <= d < day]
    after = [r.run_id for r, d in zip(runs, days, strict=True) if day < d <= day + after_days]
    lo, hi = min(a.km_from, a.km_to) - MARGIN_KM, max(a.km_from, a.km_to) + MARGIN_KM
    with db.read() as session:
        km_b, v_b = extent_profile(session, before, lo, hi, action_km=(a.km_from, a.km_to))
        km_a, v_a = extent_profile(session, after, lo, hi, action_km=(a.km_from, a.km_to))
    km = np.union1d(np.round(km_b, 6), np.round(km_a, 6))

    def on(kms: np.ndarray, vals: np.ndarray) -> list[float | None]:
        lookup = dict(zip(np.round(kms, 6).tolist(), vals.tolist(), strict=True))
        return [lookup.get(k) for k in km.tolist()]

    if not runs:
        raise ApiError(409, "action_id", f"no run of line {line.line_id!r} covers action {action_id}")
    return {
        **_out(a, line, effect, len(runs)),
        "series": [{"run_id": r.run_id, "start_time": r.run_time.isoformat(), "condition_index": float(v)}
                   for r, v in zip(runs, values, strict=True)],
        "profile_km": km.tolist(), "profile_before": on(km_b, v_b), "profile_after": on(km_a, v_a),
    }
