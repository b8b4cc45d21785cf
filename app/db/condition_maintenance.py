"""The condition index over a maintenance action's extent, per run and along km, from the store.

Values are *relative to the surrounding track of the same run*: the mean
index over the action's extent minus the mean over the ``neighbourhood_km``
around it (the extent and ``gap_km`` either side left out). What the whole
neighbourhood shares in one run — the speed the train passed at (the
provisional index is not speed-conditioned), a sensor's calibration, the
season — cancels, and what the action did to its extent remains.
"""

from __future__ import annotations

import math

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.db.condition_models import ConditionLine, ConditionRun, SegmentCondition
from app.db.condition_reader import fetch_array

__all__ = ["extent_segments", "run_levels", "extent_series", "extent_profile"]

#: Surroundings of an extent each run's level is taken from, km either side.
NEIGHBOURHOOD_KM = 1.0
#: Left out between the extent and its surroundings, km either side.
GAP_KM = 0.05


def extent_segments(km_from: float, km_to: float, seg_m: int) -> tuple[int, int]:
    """First and last segment whose centre lies in ``[km_from, km_to]`` (for an extent shorter than
    a segment: the segment holding its middle)."""
    lo, hi = sorted((km_from, km_to))
    a, b = math.ceil(lo * 1000.0 / seg_m - 0.5), math.floor(hi * 1000.0 / seg_m - 0.5)
    if b < a:
        a = b = math.floor((lo + hi) / 2 * 1000.0 / seg_m)
    return a, b


def run_levels(session: Session, line: ConditionLine, km_from: float, km_to: float, seg_m: int = 10,
               run_ids: list[int] | None = None) -> dict[int, float]:
    """Per run the mean index of the surroundings of ``[km_from, km_to]`` (the extent ± ``GAP_KM`` left out)."""
    lo, hi = sorted((km_from, km_to))
    a, b = extent_segments(lo - NEIGHBOURHOOD_KM, hi + NEIGHBOURHOOD_KM, seg_m)
    ea, eb = extent_segments(lo - GAP_KM, hi + GAP_KM, seg_m)
    sc = SegmentCondition
    stmt = select(sc.run_id, func.avg(sc.index)).where(
        sc.line_key == line.id, sc.seg_m == seg_m, sc.seg >= a, sc.seg <= b, (sc.seg < ea) | (sc.seg > eb))
    if run_ids is not None:
        stmt = stmt.where(sc.run_id.in_(run_ids))
    values = fetch_array(session, stmt.group_by(sc.run_id), 2)
    return dict(zip(values[:, 0].astype(int).tolist(), values[:, 1].tolist(), strict=True))


def extent_series(session: Session, line: ConditionLine, km_from: float, km_to: float,
                  seg_m: int = 10) -> tuple[list[ConditionRun], np.ndarray]:
    """The line's runs holding the extent (oldest first) and its index relative to the surroundings."""
    a, b = extent_segments(km_from, km_to, seg_m)
    sc = SegmentCondition
    values = fetch_array(session, select(sc.run_id, func.avg(sc.index)).where(
        sc.line_key == line.id, sc.seg_m == seg_m, sc.seg >= a, sc.seg <= b).group_by(sc.run_id), 2)
    levels = run_levels(session, line, km_from, km_to, seg_m)
    mean = {int(r): v - levels[int(r)] for r, v in values if int(r) in levels}
    if not mean:
        return [], np.zeros(0)
    runs = session.scalars(select(ConditionRun).where(ConditionRun.run_id.in_(list(mean)))).all()
    runs = sorted(runs, key=lambda r: (r.run_time, r.run_id))
    return runs, np.array([mean[r.run_id] for r in runs])


def extent_profile(session: Session, line: ConditionLine, km_from: float, km_to: float, run_ids: list[int],
                   *, action_km: tuple[float, float], seg_m: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Segment starts (km) over ``[km_from, km_to]`` and the mean over ``run_ids`` of each segment's index
    relative to the run's surroundings of ``action_km``."""
    if not run_ids:
        return np.zeros(0), np.zeros(0)
    levels = run_levels(session, line, *action_km, seg_m, run_ids)
    a, b = math.floor(min(km_from, km_to) * 1000.0 / seg_m), math.floor(max(km_from, km_to) * 1000.0 / seg_m)
    sc = SegmentCondition
    values = fetch_array(session, select(sc.run_id, sc.seg, func.avg(sc.index)).where(
        sc.run_id.in_(run_ids), sc.seg_m == seg_m, sc.seg >= a, sc.seg <= b).group_by(sc.run_id, sc.seg), 3)
    keep = np.array([int(r) in levels for r in values[:, 0]], dtype=bool)
    values = values[keep]
    if not len(values):
        return np.zeros(0), np.zeros(0)
    rel = values[:, 2] - np.array([levels[int(r)] for r in values[:, 0]])
    segs, inverse = np.unique(values[:, 1].astype(np.int64), return_inverse=True)
    mean = np.bincount(inverse, weights=rel) / np.bincount(inverse)
    return segs * seg_m / 1000.0, mean
