"""Runs of a line compared segment by segment: a run's km shift against a reference run, the
per-segment mean (amplitude or stiffness index) of every run with mean, spread and change, and
one segment over the runs' dates. The numbers come from :mod:`app.analysis.stiffness.alignment`;
``change`` compares two runs only at matched speed (:func:`app.analysis.speed_match.matched_speed`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from app.analysis.stiffness.alignment import DEFAULT_DETREND_M, Alignment, align_runs, segment_table
from app.analysis.units import KMH_PER_MPS
from app.analytics import frames as data
from app.analytics.frames import RunsQuery, Selection
from app.analytics.stiffness_index import index_context
from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.core.jsonable import finite_list, finite_or_none
from app.db import crud
from app.db.session import Database
from app.settings import Settings

__all__ = ["run_alignment", "segments", "segment_trend"]


def _alignment(sel: Selection, df: pd.DataFrame, run_id: int, ref_id: int, max_shift_m: float,
               detrend_m: float) -> Alignment | None:
    """The alignment of a run to the reference run, for every answer that reports one.

    A run aligned to itself is the identity: shift 0 and confidence 1 (nothing is estimated;
    its correlation curve is still returned)."""
    a = df[df["run_id"] == ref_id].groupby("bin")["sleeper_amp"].mean()
    b = df[df["run_id"] == run_id].groupby("bin")["sleeper_amp"].mean()
    if a.empty or b.empty:
        return None
    al = align_runs(a.index.to_numpy(), a.to_numpy(), b.index.to_numpy(), b.to_numpy(),
                    bin_length_m=sel.bin_length, max_shift_m=max_shift_m, detrend_m=detrend_m)
    if run_id == ref_id:
        al = dataclasses.replace(al, shift_m=0.0, confidence=1.0)
    return al


def run_alignment(db: Database, settings: Settings, run_id: int, *, reference_run_id: int | None,
                  max_shift_m: float, detrend_m: float) -> dict:
    """The run's amplitude signature (mean over wheels) cross-correlated with the reference run's
    (default: the earliest run of the same line/track with results)."""
    with db.read() as session:
        run = crud.get_run(session, run_id)
        if run is None:
            raise not_found("run", run_id)
    if reference_run_id is None:
        sel = data.select_runs(db, run.line_id, run.track, None) if run.line_id else \
            data.select_runs(db, None, None, [run_id])
        if run_id not in sel.run_ids:
            raise ApiError(409, "profile", _("run {run_id} has no results yet", run_id=run_id))
        reference_run_id = sel.run_ids[0]
    sel = data.select_runs(db, None, None, sorted({run_id, reference_run_id}))
    df = data.load_profiles(db, settings, sel)
    al = _alignment(sel, df, run_id, reference_run_id, max_shift_m, detrend_m)
    if al is None:
        raise ApiError(409, "profile", _("no amplitude to align (runs too short or too slow)"))
    return {"run_id": run_id, "reference_run_id": reference_run_id, "shift_m": finite_or_none(al.shift_m),
            "shift_confidence": al.confidence, "peak_r": finite_or_none(al.peak_r),
            "second_r": finite_or_none(al.second_r), "overlap_m": al.overlap_m, "lags_m": al.lags_m.tolist(),
            "correlation": finite_list(al.correlation)}


def _table(db: Database, settings: Settings, sel: Selection, km_from: float | None, km_to: float | None,
           wheel: str | None, segment_m: float, align: bool, max_shift_m: float, value: str):
    df = data.load_profiles(db, settings, sel, km_from=km_from, km_to=km_to, wheel=wheel)
    column = "sleeper_amp"
    if value == "index":
        df = index_context(db, settings, sel.line_id, sel.track, sel.bin_length).add_columns(df)
        column = "stiffness_index"
    runs, shifts, info, speeds = [], [], [], []
    ref_id = sel.run_ids[0] if sel.runs else None
    for run in sel.runs:
        per_bin = df[df["run_id"] == run.id].groupby("bin")
        g = per_bin["sleeper_amp"].mean()
        shift, conf = 0.0, None
        if align and len(g):
            al = _alignment(sel, df, run.id, ref_id, max_shift_m, DEFAULT_DETREND_M)
            if al is not None and np.isfinite(al.shift_m):
                shift, conf = al.shift_m, al.confidence
        runs.append((g.index.to_numpy(), per_bin[column].mean().to_numpy()))
        speeds.append(per_bin["speed_mean"].mean().to_numpy())
        shifts.append(shift)
        info.append({"run_id": run.id, "start_time": run.start_time.isoformat() if run.start_time else None,
                     "shift_m": shift if align else None, "shift_confidence": conf if align else None})
    table = segment_table(runs, shifts, bin_length_m=sel.bin_length, segment_m=segment_m, speeds=speeds,
                          speed_tolerance=settings.analytics_speed_tolerance,
                          statistic="median" if value == "index" else "mean")
    return ref_id, info, table


def segments(db: Database, settings: Settings, q: RunsQuery, *, segment_m: float, align: bool,
             max_shift_m: float, value: str) -> dict:
    """Runs (by start time) aligned to the first one (``align``), then averaged per segment;
    ``spread`` is the standard deviation over runs, ``change`` last minus first where the two
    passed at matched speed (else null)."""
    sel = q.select(db)
    ref_id, info, t = _table(db, settings, sel, q.km_from, q.km_to, q.wheel, segment_m, align, max_shift_m, value)
    return {"segment_m": segment_m, "value": value, "reference_run_id": ref_id, "km": (t.start_m / 1000).tolist(),
            "runs": info, "matrix": [finite_list(row) for row in t.matrix], "mean": finite_list(t.mean),
            "spread": finite_list(t.spread), "change": finite_list(t.change),
            "speed_kmh": [finite_list(row * KMH_PER_MPS) for row in t.speed],
            "speed_tolerance": settings.analytics_speed_tolerance}


def segment_trend(db: Database, settings: Settings, q: RunsQuery, *, km: float, segment_m: float, align: bool,
                  max_shift_m: float, value: str) -> dict:
    """The mean amplitude (or stiffness index) of the segment holding ``km`` in each run, by start
    time, with the run's mean speed there."""
    sel = q.select(db)
    start = np.floor(km * 1000 / segment_m) * segment_m
    lo, hi = (start - max_shift_m - 200) / 1000, (start + segment_m + max_shift_m + 200) / 1000
    _rows, info, t = _table(db, settings, sel, lo, hi, q.wheel, segment_m, align, max_shift_m, value)
    j = np.flatnonzero(np.isclose(t.start_m, start))
    points = [{"run_id": r["run_id"], "start_time": r["start_time"],
               value: finite_or_none(t.matrix[i, j[0]]) if j.size else None,
               "speed_kmh": finite_or_none(t.speed[i, j[0]] * KMH_PER_MPS) if j.size else None} for i, r in enumerate(info)]
    return {"km": km, "segment_km": [start / 1000, (start + segment_m) / 1000], "wheel": q.wheel, "value": value,
            "points": points}
