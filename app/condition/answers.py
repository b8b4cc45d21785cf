"""The answers of the ``/condition`` endpoints, from the segment condition store (never the 25 cm rows).

The routes (:mod:`app.api.condition`) parse and check the query and call one function here.
A line id (and track) without runs in the store answers 404 naming ``line_id``
(:func:`resolve_line`); a km outside the stored extent of the line 422 naming the km
parameter (:func:`check_line_km`). Index values are the store's condition index
(:mod:`app.condition.index`: ln A at matched speed), not the stiffness index of the profiles.
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
from sqlalchemy import select

from app.analysis.condition.extent_level import DEFAULT_AROUND_M, DEFAULT_MARGIN_M
from app.analysis.units import KMH_PER_MPS
from app.condition import readers as reader
from app.condition.index import STORE_INDEX
from app.condition.lines import check_line_km, resolve_line
from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.core.jsonable import finite_or_none, iso_time
from app.db import reference_crud
from app.db.models import ConditionFlag, ConditionLine, ConditionRun, Job
from app.db.session import Database

__all__ = [
    "resolve_line", "check_line_km", "lines", "heatmap", "trend", "newest_changes", "run_changes", "flags",
]


def lines(db: Database) -> dict:
    """Every line and track of the store with its extent and runs."""
    with db.read() as session:
        items = reader.list_lines(session)
    return {"items": [{
        "line_id": s.line.line_id, "track": s.line.track, "km_min": s.line.km_min, "km_max": s.line.km_max,
        "n_runs": s.n_runs, "first_run": iso_time(s.first_run), "last_run": iso_time(s.last_run),
        "last_run_id": s.last_run_id, "last_run_flags": s.last_run_flags, "reference_run_id": s.line.ref_run_id,
    } for s in items]}


def heatmap(db: Database, line_id: str, track: str | None, *, segment_m: int, wheel: str | None,
            km_from: float | None, km_to: float | None, date_from: dt.datetime | None,
            date_to: dt.datetime | None) -> dict:
    """Index per run (oldest first) × segment of a line; of one wheel or the mean over the wheels.
    ``flagged`` marks cells holding a flag of the run."""
    line = resolve_line(db, line_id, track)
    check_line_km(line, km_from=km_from, km_to=km_to)
    with db.read() as session:
        runs = reader.line_runs(session, line.id, date_from, date_to)
        hm = reader.heatmap(session, runs, segment_m, wheel=wheel, km_from=km_from, km_to=km_to)
    matrix = np.where(np.isfinite(hm.matrix), np.round(hm.matrix, 5), np.nan)
    return {
        "line_id": line.line_id, "track": line.track, "segment_m": segment_m, "wheel": wheel, "condition_index": STORE_INDEX,
        "km": (hm.seg * segment_m / 1000.0).tolist(),
        "runs": [{"run_id": r.run_id, "start_time": iso_time(r.run_time), "shift_m": r.shift_m, "n_flags": r.n_flags}
                 for r in hm.runs],
        "matrix": [[finite_or_none(v) for v in row] for row in matrix.tolist()],
        "flagged": [list(c) for c in hm.flagged],
    }


def trend(db: Database, line_id: str, track: str | None, *, km: float, segment_m: int, wheel: str | None,
          around_m: float = DEFAULT_AROUND_M, margin_m: float = DEFAULT_MARGIN_M) -> dict:
    """One segment over every run of a line (oldest first): its condition index (mean over the wheels),
    the same relative to the surrounding track of the run (:func:`app.condition.readers.extent_readings`:
    the mean within ``around_m`` of the segment outside it widened by ``margin_m``) and each wheel's row,
    with the maintenance actions that cover the segment."""
    line = resolve_line(db, line_id, track)
    check_line_km(line, km=km)
    seg = int(math.floor(km * 1000.0 / segment_m))
    lo, hi = seg * segment_m / 1000.0, (seg + 1) * segment_m / 1000.0
    with db.read() as session:
        history = reader.segment_history(session, line.id, segment_m, seg, wheel)
        flagged = set(session.scalars(select(ConditionFlag.run_id).where(
            ConditionFlag.line_key == line.id, ConditionFlag.seg_m == segment_m, ConditionFlag.seg == seg)))
        actions = reference_crud.reference_frame(session, "maintenance", line_id=line.line_id, track=line.track,
                                                 km_from=lo, km_to=hi)
        around = reader.extent_readings(session, [run.run_id for run, _ in history], lo * 1000.0, hi * 1000.0,
                                        around_m=around_m, margin_m=margin_m)
    points = []
    for run, rows in history:
        idx = [r.condition_index for r in rows if r.condition_index is not None]
        mean = float(np.mean(idx)) if idx else None
        level = around[run.run_id].around if run.run_id in around else math.nan
        points.append({
            "run_id": run.run_id, "start_time": iso_time(run.run_time), "condition_index": mean,
            "relative": mean - level if mean is not None and math.isfinite(level) else None,
            "flagged": run.run_id in flagged,
            "wheels": [{
                "wheel": r.wheel, "condition_index": float(r.condition_index),
                "condition_index_sd": finite_or_none(r.condition_index_sd),
                "amp_mean": float(r.amp_mean), "amp_p95": float(r.amp_p95), "speed_kmh": float(r.speed_mean) * KMH_PER_MPS,
                "n_valid": r.n_valid, "n_history": r.n_history, "change": finite_or_none(r.change),
                "change_z": finite_or_none(r.change_z), "trend_rate_per_year": finite_or_none(r.trend_rate),
                "trend_z": finite_or_none(r.trend_z),
            } for r in rows],
        })
    return {
        "line_id": line.line_id, "track": line.track, "segment_m": segment_m, "segment_km": [lo, hi],
        "points": points,
        "maintenance": [{"id": int(a.id), "type": a.type, "date": a.date.isoformat(), "km_from": float(a.km_from),
                         "km_to": float(a.km_to)} for a in actions.itertuples()],
    }


def _changes(db: Database, run: ConditionRun) -> dict:
    with db.read() as session:
        line = session.get(ConditionLine, run.line_key)
        run_flags = reader.run_flags(session, run.run_id)
        job = session.get(Job, run.job_id)  # its condition summary: provenance
    summary = ((job.meta or {}).get("condition") or {}) if job is not None else {}
    return {
        "run_id": run.run_id, "line_id": line.line_id, "track": line.track, "start_time": iso_time(run.run_time),
        "shift_m": run.shift_m, "history_runs": summary.get("history_runs"),
        "items": [reader.flag_dict(f, line) for f in run_flags],
    }


def newest_changes(db: Database, line_id: str, track: str | None) -> dict:
    """The flags of the line's newest run in the store, strongest first."""
    line = resolve_line(db, line_id, track)
    with db.read() as session:
        run = reader.newest_run(session, line.id)
    if run is None:
        raise ApiError(404, "line_id", _("line {line} has no runs in the condition store", line=repr(line_id)))
    return _changes(db, run)


def run_changes(db: Database, run_id: int) -> dict:
    """The flags of a run, strongest first; 404 when the run has no rows in the store."""
    with db.read() as session:
        run = session.get(ConditionRun, run_id)
    if run is None:
        raise not_found("run", run_id)
    return _changes(db, run)


def flags(db: Database, *, since: int, limit: int, line_id: str | None, track: str | None,
          new_only: bool) -> dict:
    """Flags with an id above ``since``, ascending, and the ``since`` of the next page."""
    keys = None
    if line_id is not None:
        keys = [resolve_line(db, line_id, track).id]
    with db.read() as session:
        items = reader.flags_since(session, since, limit, line_keys=keys, only_new=new_only)
        by_key = {ln.id: ln for ln in session.scalars(
            select(ConditionLine).where(ConditionLine.id.in_({f.line_key for f in items})))}
    return {"items": [reader.flag_dict(f, by_key[f.line_key]) for f in items],
            "next_since": items[-1].id if items else since}
