"""The condition index over a stretch of line, per run and along km, relative to its surroundings.

Values are *relative to the surrounding track of the same run*: the index over
the stretch minus the run's mean over the ``NEIGHBOURHOOD_KM`` either side
(the stretch and ``GAP_KM`` either side left out; from the runs' 100 m overview
rows). What the whole neighbourhood shares in one run — the speed the train
passed at (the provisional index is not speed-conditioned), a sensor's
calibration, the season — cancels, and what happened to the stretch remains.
The rows are read run by run through the primary keys (a stretch of a year of
daily runs: a few thousand rows).
"""

from __future__ import annotations

import math

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.condition.readers import OVERVIEW_M, line_runs
from app.db.models import ConditionLine, ConditionOverview, ConditionRun, SegmentCondition
from app.db.numeric import fetch_numeric
from app.io import WHEELS

__all__ = ["NEIGHBOURHOOD_KM", "GAP_KM", "extent_segments", "run_levels", "extent_series", "extent_profile"]

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
    values = fetch_numeric(session, select(o.run_id, func.avg(o.index)).where(
        o.run_id.in_(runs), o.seg >= a, o.seg <= b, (o.seg < ea) | (o.seg > eb)).group_by(o.run_id), 2)
    return dict(zip(values[:, 0].astype(int).tolist(), values[:, 1].tolist(), strict=True))


def _wheel_rows(session: Session, runs: list[int], seg_m: int, a: int, b: int, *, by_seg: bool) -> np.ndarray:
    """``(run_id, [seg,] mean index over the wheels)`` of segments a…b of the runs (primary-key ranges)."""
    sc = SegmentCondition
    keys = (sc.run_id, sc.seg) if by_seg else (sc.run_id,)
    stmt = select(*keys, func.avg(sc.index)).where(
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
