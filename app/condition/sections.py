"""Section classes of a line (EN 13848-6 / CEN TR 16513 style): per section (200 m by default) a
class A … E from the speed-conditioned stiffness index of the store's 10 m rows, for the newest
run and for the newest run at least a year before it, with the length per class.

The index is ``ln(A / A_ref(class, v))`` per 10 m segment, mean over the wheels — the quantity the
places are graded on (docs/places.md): ``A_ref`` is fitted from the 10 m rows of the line's last
``TRACKVKF_PLACES_HISTORY_RUNS`` runs up to the run classed (:func:`app.analysis.condition.segment_curves.fit_segment_curves`,
superstructure classes from the reference data with ``TRACKVKF_ANALYTICS_SECTION_MARGIN_M`` left
out around a change of type); the classes come from
:func:`app.analysis.condition.section_class.section_classes`.
"""

from __future__ import annotations

import datetime as dt
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from app.analysis.condition.run_places import segment_index
from app.analysis.condition.section_class import (
    DEFAULT_SECTION_LIMITS,
    SECTION_CLASSES,
    SectionClassLimits,
    section_classes,
)
from app.analysis.condition.segment_curves import fit_segment_curves
from app.analysis.stiffness.superstructure import section_classes as superstructure_at
from app.condition import readers as reader
from app.condition.lines import resolve_line
from app.db import reference_crud
from app.db.models import ConditionLine, ConditionRun, SegmentCondition
from app.db.session import Database

__all__ = ["SEGMENT_M", "line_sections", "section_limits"]

#: the store's fine segments the classes are read from, m
SEGMENT_M = 10
_YEAR = dt.timedelta(days=365)


def _rows(session: Session, run_ids: list[int]) -> dict[int, tuple[np.ndarray, list[str], np.ndarray, np.ndarray]]:
    """Per run: segments, wheels, ln A and speed (wheels × segments) of its 10 m rows."""
    sc = SegmentCondition
    res = session.execute(select(sc.run_id, sc.wheel, sc.seg, sc.index, sc.speed_mean)
                          .where(sc.run_id.in_(run_ids), sc.seg_m == SEGMENT_M)).all()
    out = {}
    if not res:
        return out
    run = np.array([r[0] for r in res], dtype=np.int64)
    wheel = np.array([r[1] for r in res], dtype=object)
    seg = np.array([r[2] for r in res], dtype=np.int64)
    la = np.array([np.nan if r[3] is None else r[3] for r in res], dtype=np.float64)
    v = np.array([np.nan if r[4] is None else r[4] for r in res], dtype=np.float64)
    for rid in np.unique(run).tolist():
        m = run == rid
        segs = np.unique(seg[m])
        wheels = sorted(set(wheel[m].tolist()))
        a = np.full((len(wheels), segs.size), np.nan)
        s = np.full((len(wheels), segs.size), np.nan)
        for i, w in enumerate(wheels):
            k = m & (wheel == w)
            j = np.searchsorted(segs, seg[k])
            a[i, j] = la[k]
            s[i, j] = v[k]
        out[int(rid)] = (segs, wheels, a, s)
    return out


def _classes(session: Session, line: ConditionLine, segs: np.ndarray, margin_m: float) -> np.ndarray:
    frame = reference_crud.reference_frame(session, "superstructure", line_id=line.line_id, track=line.track)
    if frame is None or len(frame) == 0:
        return np.array([""] * segs.size, dtype=object)
    return superstructure_at((segs + 0.5) * SEGMENT_M, frame["km_from"].to_numpy() * 1000.0,
                             frame["km_to"].to_numpy() * 1000.0, frame["type"].to_numpy(dtype=object),
                             boundary_margin_m=margin_m)


def _run_index(session: Session, line: ConditionLine, runs: list[ConditionRun], k: int, *,
               speed_tolerance: float, margin_m: float, history_runs: int,
               min_locations: int) -> tuple[np.ndarray, np.ndarray]:
    """The index of run ``runs[k]`` per 10 m segment (mean over wheels), curves from the runs up to it."""
    used = runs[max(0, k - history_runs + 1): k + 1]
    rows = _rows(session, [r.run_id for r in used])
    target = runs[k].run_id
    if target not in rows:
        return np.zeros(0, np.int64), np.zeros(0)
    cls = {rid: _classes(session, line, segs, margin_m) for rid, (segs, *_rest) in rows.items()}
    parts = [(segs, a[i], v[i], np.full(segs.size, rid), np.full(segs.size, w, dtype=object), cls[rid])
             for rid, (segs, wheels, a, v) in rows.items() for i, w in enumerate(wheels)]
    curves = fit_segment_curves(*[np.concatenate([p[j] for p in parts]) for j in range(6)],
                                speed_tolerance=speed_tolerance, min_locations=min_locations)
    segs, _, a, v = rows[target]
    idx = segment_index(a, v, cls[target], curves)
    n = np.isfinite(idx).sum(axis=0)
    mean = np.where(n > 0, np.nansum(np.where(np.isfinite(idx), idx, 0.0), axis=0) / np.maximum(n, 1), np.nan)
    return segs, mean


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def section_limits(settings: Any) -> SectionClassLimits:
    """``TRACKVKF_PLACES_SECTION_LIMITS`` (default :data:`~app.analysis.condition.section_class.DEFAULT_SECTION_LIMITS`)."""
    lim = getattr(settings, "places_section_limits", None)
    return SectionClassLimits(*lim) if lim else DEFAULT_SECTION_LIMITS


def line_sections(db: Database, settings: Any, line_id: str, track: str | None, *,
                  section_m: float | None = None) -> dict[str, Any]:
    """The section classes of a line's newest run, and the length per class now and a year before.

    Parameters
    ----------
    db : Database
    settings : Settings
        ``analytics_speed_tolerance`` (the matched-speed window of the curves),
        ``analytics_section_margin_m``, ``places_history_runs`` (runs the curves are fitted on),
        ``places_curve_min_locations``, ``places_section_m`` and ``places_section_limits``.
    line_id, track : str
        The store's line (404 naming ``line_id`` without runs, 422 naming ``track`` when ambiguous).
    section_m : float, optional
        Section length, m (a whole multiple of 10 m; default ``places_section_m``).

    Returns
    -------
    dict
        ``section_m, limits, sections [{km_from, km_to, class, level, spread, rms, fill}],
        length_by_class {A..E, "": m}, length_by_class_year_ago (or None), run_id, run_time,
        run_id_year_ago, run_time_year_ago``.
    """
    line = resolve_line(db, line_id, track)
    limits = section_limits(settings)
    section_m = float(section_m if section_m is not None else settings.places_section_m)
    fit = {"speed_tolerance": float(settings.analytics_speed_tolerance),
           "margin_m": float(settings.analytics_section_margin_m),
           "history_runs": int(settings.places_history_runs),
           "min_locations": int(settings.places_curve_min_locations)}
    with db.read() as session:
        runs = reader.line_runs(session, line.id)
        k = len(runs) - 1
        segs, idx = _run_index(session, line, runs, k, **fit)
        sc = section_classes(segs, idx, segment_m=SEGMENT_M, limits=limits, section_m=section_m)
        before = [i for i, r in enumerate(runs) if r.run_time <= runs[k].run_time - _YEAR]
        old = None
        if before:
            j = before[-1]
            osegs, oidx = _run_index(session, line, runs, j, **fit)
            old = (runs[j], section_classes(osegs, oidx, segment_m=SEGMENT_M, limits=limits, section_m=section_m))
    per = int(round(section_m / SEGMENT_M))
    sections = [
        {"km_from": float(sc.start_m[i]) / 1000.0, "km_to": float(sc.end_m[i]) / 1000.0, "class": str(sc.cls[i]),
         "level": _finite(sc.level[i]), "spread": _finite(sc.spread[i]), "rms": _finite(sc.rms[i]),
         "fill": float(sc.n_segments[i]) / per}
        for i in range(len(sc))
    ]
    return {
        "line_id": line.line_id, "track": line.track, "section_m": float(section_m),
        "limits": limits.limits.tolist(), "classes": list(SECTION_CLASSES),
        "quantity": "stiffness index ln(A/A_ref(class, v)), mean over the wheels",
        "sections": sections, "length_by_class": sc.length_by_class(),
        "length_by_class_year_ago": old[1].length_by_class() if old else None,
        "run_id": runs[k].run_id, "run_time": runs[k].run_time,
        "run_id_year_ago": old[0].run_id if old else None, "run_time_year_ago": old[0].run_time if old else None,
    }
