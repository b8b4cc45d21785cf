"""A line's hotspots from the segment condition store: its newest run's segments ranked
(:func:`app.analysis.condition.rank_segments`), with their superstructure class."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from app.analysis.condition import (
    DEFAULT_ANOMALY_Z,
    DEFAULT_CHANGE_PARAMS,
    TREND_SEGMENT_M,
    ChangeParams,
    HotspotTable,
    rank_segments,
)
from app.analysis.stiffness.superstructure import assign_sections
from app.condition.readers import newest_run
from app.db import reference_crud
from app.db.models import ConditionLine, ConditionRun, SegmentCondition
from app.db.numeric import fetch_numeric

__all__ = ["LineHotspots", "line_hotspots", "UNCLASSIFIED"]

#: Class of segments outside every imported superstructure section.
UNCLASSIFIED = ""
_COLUMNS = ("index", "change", "change_z", "trend_rate", "trend_z")


@dataclass(frozen=True)
class LineHotspots:
    """The ranked segments of a line's run.

    Attributes
    ----------
    line : ConditionLine
    run : ConditionRun
    seg_m : int
        Segment length, m.
    table : HotspotTable
        Evidence and priority per segment (segment order).
    classes : numpy.ndarray
        Superstructure class per segment (:data:`UNCLASSIFIED` outside the sections).
    """

    line: ConditionLine
    run: ConditionRun
    seg_m: int
    table: HotspotTable
    classes: np.ndarray


def _wheel_matrices(session: Session, run_id: int, seg_m: int) -> tuple[np.ndarray, list[str], np.ndarray]:
    """(segments, wheels, values (columns, wheels, segments)) of a run's rows of one length."""
    sc = SegmentCondition
    wheels = sorted(session.scalars(select(sc.wheel).where(sc.run_id == run_id, sc.seg_m == seg_m).distinct()))
    per = {}
    for w in wheels:
        per[w] = fetch_numeric(session, select(sc.seg, *(getattr(sc, c) for c in _COLUMNS)).where(
            sc.run_id == run_id, sc.seg_m == seg_m, sc.wheel == w).order_by(sc.seg), 1 + len(_COLUMNS))
    segs = np.unique(np.concatenate([a[:, 0] for a in per.values()])).astype(np.int64) if per else np.zeros(0, np.int64)
    values = np.full((len(_COLUMNS), len(wheels), segs.size), np.nan)
    for i, w in enumerate(wheels):
        a = per[w]
        j = np.searchsorted(segs, a[:, 0].astype(np.int64))
        values[:, i, j] = a[:, 1:].T
    return segs, wheels, values


def line_hotspots(
    session: Session, line: ConditionLine, seg_m: int, *, run: ConditionRun | None = None,
    params: ChangeParams = DEFAULT_CHANGE_PARAMS, anomaly_z: float = DEFAULT_ANOMALY_Z,
) -> LineHotspots | None:
    """Rank the segments of ``run`` (default: the line's newest) of length ``seg_m``; None without runs.

    The rate of a 10 m segment is that of the 100 m segment holding it; the class is the
    imported superstructure section holding the segment's centre.
    """
    run = run or newest_run(session, line.id)
    if run is None:
        return None
    segs, wheels, v = _wheel_matrices(session, run.run_id, seg_m)
    idx, chg, cz, rate, tz = v
    trend_m = int(TREND_SEGMENT_M)
    if seg_m != trend_m and segs.size:  # the trend of the trend-test segment holding each segment
        parent, parent_wheels, pv = _wheel_matrices(session, run.run_id, trend_m)
        rate, tz = np.full_like(idx, np.nan), np.full_like(idx, np.nan)
        if parent.size:
            up = segs * seg_m // trend_m
            j = np.minimum(np.searchsorted(parent, up), parent.size - 1)
            hit = parent[j] == up
            for i, w in enumerate(wheels):
                if w in parent_wheels:
                    k = parent_wheels.index(w)
                    rate[i, hit] = pv[3, k, j[hit]]
                    tz[i, hit] = pv[4, k, j[hit]]
    sections = reference_crud.reference_frame(session, "superstructure", line_id=line.line_id, track=line.track)
    classes = np.full(segs.size, UNCLASSIFIED, dtype=object)
    if len(sections) and segs.size:
        k = assign_sections((segs + 0.5) * seg_m, sections["km_from"].to_numpy() * 1000.0,
                            sections["km_to"].to_numpy() * 1000.0)
        types = sections["type"].to_numpy(dtype=object)
        classes = np.where(k >= 0, types[np.maximum(k, 0)], UNCLASSIFIED).astype(object)
    table = rank_segments(segs, classes, idx, chg, cz, rate, tz, params=params, anomaly_z=anomaly_z)
    return LineHotspots(line, run, seg_m, table, classes)
