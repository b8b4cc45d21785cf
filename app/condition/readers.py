"""Queries of the segment condition store: lines, heat maps, trends, change lists, the flag feed.

Everything here reads the segment rows (:mod:`app.db.models`),
never the 25 cm profile rows: a year of daily runs over a line is a few
hundred thousand rows at 100 m, read straight from the database cursor into
numpy arrays.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from sqlalchemy import func, literal, select
from sqlalchemy.orm import Session

from app.analysis.condition import FINE_SEGMENT_M, OVERVIEW_SEGMENT_M
from app.analysis.condition.extent_level import (
    DEFAULT_AROUND_M,
    DEFAULT_MARGIN_M,
    DEFAULT_MIN_SEGMENTS,
    extent_level,
    like_surroundings,
    surroundings_level,
)
from app.core.jsonable import finite_or_none, iso_time
from app.db.models import (
    ConditionFlag,
    ConditionLine,
    ConditionOverview,
    ConditionRun,
    SegmentCondition,
)
from app.db.numeric import fetch_numeric
from app.io import WHEELS

__all__ = [
    "LineSummary",
    "Heatmap",
    "list_lines",
    "find_lines",
    "line_runs",
    "heatmap",
    "segment_history",
    "run_flags",
    "flags_since",
    "newest_run",
    "flag_dict",
    "wheel_mean_rows",
    "ExtentReading",
    "extent_readings",
]


#: Segment length of the overview rows, m (:data:`app.analysis.condition.OVERVIEW_SEGMENT_M`).
OVERVIEW_M = int(OVERVIEW_SEGMENT_M)


@dataclass(frozen=True)
class LineSummary:
    """A line and track of the store with its extent and runs."""

    line: ConditionLine
    n_runs: int
    first_run: dt.datetime | None
    last_run: dt.datetime | None
    last_run_id: int | None
    last_run_flags: int


@dataclass(frozen=True)
class Heatmap:
    """Index per run (rows, oldest first) and segment (columns).

    Attributes
    ----------
    runs : list of ConditionRun
    seg : numpy.ndarray
        Segment numbers of the columns.
    matrix : numpy.ndarray
        (runs, segments) index (mean over the wheels asked for; NaN = none).
    flagged : list of (int, int)
        (row, column) of the cells with a flag of the run in the segment (a
        flag of a shorter segment marks the cell holding it).
    """

    runs: list[ConditionRun]
    seg: np.ndarray
    matrix: np.ndarray
    flagged: list[tuple[int, int]]


def list_lines(session: Session) -> list[LineSummary]:
    """Every line and track of the store with runs, by line id and track."""
    stats = {
        key: (n, first, last)
        for key, n, first, last in session.execute(
            select(ConditionRun.line_key, func.count(), func.min(ConditionRun.run_time),
                   func.max(ConditionRun.run_time)).group_by(ConditionRun.line_key)
        ).all()
    }
    out = []
    for line in session.scalars(select(ConditionLine).order_by(ConditionLine.line_id, ConditionLine.track)):
        if line.id not in stats:  # its runs were deleted or moved to another line
            continue
        n, first, last = stats[line.id]
        newest = newest_run(session, line.id)
        out.append(LineSummary(line, int(n), first, last, newest.run_id if newest else None,
                               newest.n_flags if newest else 0))
    return out


def find_lines(session: Session, line_id: str, track: str | None) -> list[ConditionLine]:
    """The store's lines of ``line_id`` (and ``track`` when given) that hold runs."""
    has_runs = select(ConditionRun.run_id).where(ConditionRun.line_key == ConditionLine.id).exists()
    stmt = select(ConditionLine).where(ConditionLine.line_id == line_id, has_runs)
    if track is not None:
        stmt = stmt.where(ConditionLine.track == track)
    return list(session.scalars(stmt.order_by(ConditionLine.track)))


def newest_run(session: Session, line_key: int) -> ConditionRun | None:
    """The line's newest run in the store."""
    return session.scalars(
        select(ConditionRun).where(ConditionRun.line_key == line_key)
        .order_by(ConditionRun.run_time.desc(), ConditionRun.run_id.desc()).limit(1)
    ).first()


def line_runs(session: Session, line_key: int, date_from: dt.datetime | None = None,
              date_to: dt.datetime | None = None) -> list[ConditionRun]:
    """The line's runs in the store, oldest first, optionally within a time range."""
    stmt = select(ConditionRun).where(ConditionRun.line_key == line_key)
    if date_from is not None:
        stmt = stmt.where(ConditionRun.run_time >= date_from)
    if date_to is not None:
        stmt = stmt.where(ConditionRun.run_time <= date_to)
    return list(session.scalars(stmt.order_by(ConditionRun.run_time, ConditionRun.run_id)))


def _seg_range(seg_m: int, km_from: float | None, km_to: float | None) -> tuple[int | None, int | None]:
    lo = int(np.floor(km_from * 1000.0 / seg_m)) if km_from is not None else None
    hi = int(np.floor(km_to * 1000.0 / seg_m - 1e-9)) if km_to is not None else None
    return lo, hi


def heatmap(session: Session, runs: Sequence[ConditionRun], seg_m: int, *, wheel: str | None = None,
            km_from: float | None = None, km_to: float | None = None) -> Heatmap:
    """Index of every run and segment of ``seg_m`` in a km range (mean over wheels unless ``wheel``).

    The line overview (100 m, mean over the wheels) reads the runs' overview rows
    (:class:`~app.db.models.ConditionOverview`); other views the segment rows.
    """
    run_ids = [r.run_id for r in runs]
    if not run_ids:
        return Heatmap([], np.zeros(0, np.int64), np.zeros((0, 0)), [])
    lo, hi = _seg_range(seg_m, km_from, km_to)
    overview = wheel is None and seg_m == OVERVIEW_M
    t = ConditionOverview if overview else SegmentCondition
    conds = [t.run_id.in_(run_ids)]
    if not overview:
        conds.append(SegmentCondition.seg_m == seg_m)
        if wheel is not None:
            conds.append(SegmentCondition.wheel == wheel)
    if lo is not None:
        conds.append(t.seg >= lo)
    if hi is not None:
        conds.append(t.seg <= hi)
    if overview:
        stmt = select(t.run_id, t.seg, t.condition_index, t.flagged).where(*conds)
    elif wheel is None:
        stmt = select(t.run_id, t.seg, func.avg(t.condition_index), literal(0)).where(*conds).group_by(t.run_id, t.seg)
    else:
        stmt = select(t.run_id, t.seg, t.condition_index, literal(0)).where(*conds)
    values = fetch_numeric(session, stmt, 4)
    segs = np.unique(values[:, 1].astype(np.int64)) if len(values) else np.zeros(0, np.int64)
    order = np.argsort(run_ids)
    sorted_ids = np.asarray(run_ids, dtype=np.int64)[order]
    rows = order[np.searchsorted(sorted_ids, values[:, 0].astype(np.int64))] if len(values) else np.zeros(0, int)
    cols = np.searchsorted(segs, values[:, 1].astype(np.int64))
    matrix = np.full((len(run_ids), segs.size), np.nan)
    matrix[rows, cols] = values[:, 2]
    if overview:
        hit = values[:, 3] > 0
        flagged = set(zip(rows[hit].tolist(), cols[hit].tolist(), strict=True))
    else:
        fl = fetch_numeric(session, select(ConditionFlag.run_id, ConditionFlag.seg_m, ConditionFlag.seg).where(
            ConditionFlag.run_id.in_(run_ids), ConditionFlag.seg_m <= seg_m), 3)
        cell = np.floor(fl[:, 2] * fl[:, 1] / seg_m).astype(np.int64)
        j = np.minimum(np.searchsorted(segs, cell), max(segs.size - 1, 0))
        hit = (segs.size > 0) & (segs[j] == cell) if segs.size else np.zeros(len(fl), dtype=bool)
        fr = order[np.searchsorted(sorted_ids, fl[:, 0].astype(np.int64))] if len(fl) else np.zeros(0, int)
        flagged = set(zip(fr[hit].tolist(), j[hit].tolist(), strict=True))
    return Heatmap(list(runs), segs, matrix, sorted(flagged))


def segment_history(session: Session, line_key: int, seg_m: int, seg: int,
                    wheel: str | None = None) -> list[tuple[ConditionRun, list[SegmentCondition]]]:
    """One segment's rows in every run of the line (oldest run first), per run the rows of its wheels."""
    sc = SegmentCondition
    stmt = select(sc).where(sc.line_key == line_key, sc.seg_m == seg_m, sc.seg == seg)
    if wheel is not None:
        stmt = stmt.where(sc.wheel == wheel)
    rows = list(session.scalars(stmt))
    by_run: dict[int, list[SegmentCondition]] = {}
    for r in rows:
        by_run.setdefault(r.run_id, []).append(r)
    if not by_run:
        return []
    runs = session.scalars(select(ConditionRun).where(ConditionRun.run_id.in_(list(by_run)))).all()
    runs = sorted(runs, key=lambda r: (r.run_time, r.run_id))
    return [(r, sorted(by_run[r.run_id], key=lambda x: x.wheel)) for r in runs]


def run_flags(session: Session, run_id: int) -> list[ConditionFlag]:
    """A run's flags, strongest first."""
    flags = list(session.scalars(select(ConditionFlag).where(ConditionFlag.run_id == run_id)))
    return sorted(flags, key=lambda f: -abs(f.score))


def flags_since(session: Session, since: int, limit: int, *, line_keys: Sequence[int] | None = None,
                only_new: bool = False) -> list[ConditionFlag]:
    """Flags with an id above ``since``, ascending (the feed; see :class:`ConditionFlag`)."""
    stmt = select(ConditionFlag).where(ConditionFlag.id > since)
    if line_keys is not None:
        stmt = stmt.where(ConditionFlag.line_key.in_(list(line_keys)))
    if only_new:
        stmt = stmt.where(ConditionFlag.is_new.is_(True))
    return list(session.scalars(stmt.order_by(ConditionFlag.id).limit(limit)))


def flag_dict(f: ConditionFlag, line: ConditionLine) -> dict:
    """A flag as the API answers it and the webhooks send it (km in km, change also in %)."""
    change = finite_or_none(f.change)
    return {
        "id": f.id, "run_id": f.run_id, "line_id": line.line_id, "track": line.track,
        "km_from": f.seg * f.seg_m / 1000.0, "km_to": (f.seg + 1) * f.seg_m / 1000.0, "segment_m": f.seg_m,
        "kind": f.kind, "direction": "up" if f.direction > 0 else "down", "score": float(f.score),
        "change": change, "change_pct": 100.0 * math.expm1(change) if change is not None else None,
        "rate_per_year": finite_or_none(f.rate_per_year), "wheels": [w for w in f.wheels.split(",") if w],
        "is_new": bool(f.is_new), "created_at": iso_time(f.created_at),
    }


def wheel_mean_rows(session: Session, run_ids: Sequence[int], seg_m: int, first: int, last: int, *,
                    speed: bool = False) -> np.ndarray:
    """(n, 3) float64 ``(run_id, seg, condition index mean over the wheels)`` of segments ``first … last`` of
    ``seg_m`` m of the runs, ordered by run and segment (read through the primary key); ``speed``: a fourth
    column, the speed over the segment (m/s, mean over the wheels)."""
    cols = 4 if speed else 3
    if not run_ids:
        return np.zeros((0, cols))
    sc = SegmentCondition
    extra = (func.avg(sc.speed_mean),) if speed else ()
    stmt = select(sc.run_id, sc.seg, func.avg(sc.condition_index), *extra).where(
        sc.run_id.in_([int(r) for r in run_ids]), sc.seg_m == int(seg_m), sc.wheel.in_(list(WHEELS)),
        sc.seg >= int(first), sc.seg <= int(last)).group_by(sc.run_id, sc.seg).order_by(sc.run_id, sc.seg)
    return fetch_numeric(session, stmt, cols)


@dataclass(frozen=True)
class ExtentReading:
    """One run's condition index over an extent, read against the track around it.

    Attributes
    ----------
    level : float
        :func:`~app.analysis.condition.extent_level.extent_level`: the median inside minus the
        surroundings' level (ln units; NaN: too few values on either side).
    around : float
        :func:`~app.analysis.condition.extent_level.surroundings_level` (ln units; NaN: too few values).
    seg : numpy.ndarray
        Segments read (int64; the extent and its surroundings).
    index : numpy.ndarray
        Their condition index, mean over the wheels.
    speed : float
        The run's speed over the extent (median over its segments, m/s; NaN: not read).
    """

    level: float
    around: float
    seg: np.ndarray
    index: np.ndarray
    speed: float = math.nan


def extent_readings(session: Session, run_ids: Sequence[int], start_m: float, end_m: float, *,
                    around_m: float = DEFAULT_AROUND_M, margin_m: float = DEFAULT_MARGIN_M,
                    seg_m: int = int(FINE_SEGMENT_M), speed_tolerance: float | None = None,
                    classes: Callable[[np.ndarray], np.ndarray] | None = None) -> dict[int, ExtentReading]:
    """Per run (those with rows there) the condition index over ``[start_m, end_m)`` (m on the aligned km axis)
    against its surroundings, from the store's ``seg_m`` rows (mean over the wheels): the one rule of an
    extent against the track around it (:mod:`app.analysis.condition.extent_level`, ``around_m`` and
    ``margin_m``: ``TRACKVKF_PLACES_EFFECT_AROUND_M`` / ``_MARGIN_M``).

    An extent holding fewer segment centres than
    :data:`~app.analysis.condition.extent_level.DEFAULT_MIN_SEGMENTS` needs a value on each of them (one
    shorter than a segment: the segment holding its middle).

    With ``speed_tolerance`` (the matched-speed rule's) the surroundings are only the segments the run passed
    at the extent's speed, and with ``classes`` (the superstructure class of given segments) only those of the
    extent's own class, else any class at its speed
    (:func:`~app.analysis.condition.extent_level.like_surroundings`); each reading then has the run's speed.
    """
    lo, hi = sorted((float(start_m), float(end_m)))
    if hi - lo < seg_m and math.floor(lo / seg_m - 0.5) == math.floor(hi / seg_m - 0.5):
        # no segment centre inside: the segment holding the middle
        k = math.floor((lo + hi) / 2 / seg_m)
        lo, hi = k * seg_m, (k + 1) * seg_m
    n_inside = max(math.ceil(hi / seg_m - 0.5) - math.ceil(lo / seg_m - 0.5), 1)
    mid = 0.5 * (lo + hi)
    first = math.floor(min(lo, mid - around_m) / seg_m)
    last = math.floor(max(hi, mid + around_m) / seg_m)
    alike = speed_tolerance is not None
    values = wheel_mean_rows(session, run_ids, seg_m, first, last, speed=alike)
    out: dict[int, ExtentReading] = {}
    if not len(values):
        return out
    cls_all = classes(np.arange(first, last + 1, dtype=np.int64)) if classes is not None else None
    runs, starts = np.unique(values[:, 0].astype(np.int64), return_index=True)
    kw = {"segment_m": float(seg_m), "around_m": around_m, "margin_m": margin_m}
    for run_id, a, b in zip(runs.tolist(), starts.tolist(), [*starts[1:].tolist(), len(values)], strict=True):
        seg, x = values[a:b, 1].astype(np.int64), values[a:b, 2]
        masks, v = [np.ones(seg.size, dtype=bool)], math.nan
        if alike:
            centres = (seg + 0.5) * seg_m
            inside = (centres >= lo) & (centres < hi)
            sv = values[a:b, 3]
            v = float(np.nanmedian(sv[inside])) if np.isfinite(sv[inside]).any() else math.nan
            masks = like_surroundings(inside, cls_all[seg - first] if cls_all is not None else None, sv,
                                      float(speed_tolerance))
        level = around = math.nan
        for keep in masks:
            xk = np.where(keep, x, np.nan)
            level = extent_level(seg, xk, lo, hi, min_inside=min(n_inside, DEFAULT_MIN_SEGMENTS), **kw)
            around = surroundings_level(seg, xk, lo, hi, **kw)
            if math.isfinite(level):
                break
        out[int(run_id)] = ExtentReading(level=level, around=around, seg=seg, index=x, speed=v)
    return out

