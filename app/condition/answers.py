"""The answers of the ``/condition`` endpoints, from the segment condition store (never the 25 cm rows).

The routes (:mod:`app.api.condition`) parse and check the query and call one function here.
A line id (and track) without runs in the store answers 404 naming ``line_id``
(:func:`resolve_line`); a km outside the stored extent of the line 422 naming the km
parameter (:func:`check_line_km`). Index values are the store's condition index
(:mod:`app.condition.index`: ln A at matched speed), not the stiffness index of the profiles.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import math
from dataclasses import dataclass

import numpy as np
from sqlalchemy import select

from app.condition import readers as reader
from app.condition.config import FLEET_SOURCE_FORMAT, ConditionConfig
from app.condition.hotspots import line_hotspots
from app.condition.index import STORE_INDEX
from app.condition.lines import check_line_km, resolve_line
from app.condition.maintenance import run_levels
from app.core.config import Settings
from app.core.errors import ApiError, not_found
from app.core.jsonable import finite_or_none, iso_time
from app.db import recorder_crud, reference_crud
from app.db.models import ConditionFlag, ConditionLine, ConditionRun, Job, JobStatus, Run
from app.db.session import Database

__all__ = [
    "resolve_line", "check_line_km", "lines", "heatmap", "trend", "newest_changes", "run_changes", "flags",
    "HotspotQuery", "hotspots", "hotspots_csv", "hotspots_geojson", "HOTSPOT_CSV_COLUMNS",
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
        "line_id": line.line_id, "track": line.track, "segment_m": segment_m, "wheel": wheel, "index": STORE_INDEX,
        "km": (hm.seg * segment_m / 1000.0).tolist(),
        "runs": [{"run_id": r.run_id, "start_time": iso_time(r.run_time), "shift_m": r.shift_m, "n_flags": r.n_flags}
                 for r in hm.runs],
        "matrix": [[finite_or_none(v) for v in row] for row in matrix.tolist()],
        "flagged": [list(c) for c in hm.flagged],
    }


def trend(db: Database, line_id: str, track: str | None, *, km: float, segment_m: int, wheel: str | None) -> dict:
    """One segment over every run of a line (oldest first): its index (mean over the wheels), the
    same relative to the surrounding track of the run (±1 km) and each wheel's row, with the
    maintenance actions that cover the segment."""
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
        levels = run_levels(session, [run.run_id for run, _ in history], lo, hi)
    points = []
    for run, rows in history:
        idx = [r.index for r in rows if r.index is not None]
        mean = float(np.mean(idx)) if idx else None
        level = levels.get(run.run_id)
        points.append({
            "run_id": run.run_id, "start_time": iso_time(run.run_time), "index": mean,
            "relative": mean - level if mean is not None and level is not None else None,
            "flagged": run.run_id in flagged,
            "wheels": [{
                "wheel": r.wheel, "index": float(r.index), "index_sd": finite_or_none(r.index_sd),
                "amp_mean": float(r.amp_mean), "amp_p95": float(r.amp_p95), "speed_kmh": float(r.speed_mean) * 3.6,
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
        raise ApiError(404, "line_id", f"line {line_id!r} has no runs in the condition store")
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


# --- hotspots: the work list ---------------------------------------------------------------
@dataclass(frozen=True)
class HotspotQuery:
    """Filters of the work list (JSON, CSV and GeoJSON alike), checked by the route."""

    line_id: str | None
    track: str | None
    km_from: float | None
    km_to: float | None
    superstructure: str | None
    segment_m: int
    min_priority: float
    limit: int


def _map_run(session, line: ConditionLine) -> int | None:
    """The line's newest run whose 25 cm rows are there (what the stiffness map shows)."""
    return session.scalar(
        select(Run.id).where(Run.line_id == line.line_id, Run.track == line.track,
                             Run.source_format != FLEET_SOURCE_FORMAT,
                             select(Job.id).where(Job.run_id == Run.id, Job.status == JobStatus.DONE).exists())
        .order_by(Run.start_time.desc(), Run.id.desc()).limit(1))


def _hotspots(db: Database, settings: Settings, q: HotspotQuery) -> tuple[int, list[dict], dict[int, ConditionLine]]:
    """(matching count, items ranked by priority, lines by key)."""
    if q.line_id is not None:
        chosen = [resolve_line(db, q.line_id, q.track)]
        check_line_km(chosen[0], km_from=q.km_from, km_to=q.km_to)
    else:
        if q.km_from is not None or q.km_to is not None:
            raise ApiError(422, "line_id", "is required with km_from / km_to")
        with db.read() as session:
            chosen = [s.line for s in reader.list_lines(session)
                      if q.track is None or s.line.track == q.track]
    params = ConditionConfig.from_settings(settings).change
    items = []
    with db.read() as session:
        for line in chosen:
            hs = line_hotspots(session, line, q.segment_m, params=params)
            if hs is None:
                continue
            t = hs.table
            keep = t.priority >= q.min_priority
            start = t.seg * q.segment_m / 1000.0
            if q.km_from is not None:
                keep &= start + q.segment_m / 1000.0 > q.km_from
            if q.km_to is not None:
                keep &= start < q.km_to
            if q.superstructure is not None:
                keep &= hs.classes == q.superstructure
            map_run = _map_run(session, line)
            for j in np.flatnonzero(keep):
                lo = float(start[j])
                hi = lo + q.segment_m / 1000.0
                change, rate = finite_or_none(t.change[j]), finite_or_none(t.rate_per_year[j])
                items.append({
                    "line_key": line.id, "line_id": line.line_id, "track": line.track, "km_from": lo, "km_to": hi,
                    "segment_m": q.segment_m, "superstructure": str(hs.classes[j]), "index": finite_or_none(t.index[j]),
                    "anomaly_z": finite_or_none(t.anomaly_z[j]), "change": change,
                    "change_pct": 100.0 * math.expm1(change) if change is not None else None,
                    "change_z": finite_or_none(t.change_z[j]), "rate_per_year": rate,
                    "rate_pct_per_year": 100.0 * math.expm1(rate) if rate is not None else None,
                    "trend_z": finite_or_none(t.trend_z[j]), "wheels_agreeing": int(t.agreeing[j]),
                    "n_wheels": int(t.n_wheels[j]), "priority": float(t.priority[j]),
                    "direction": "up" if t.direction[j] > 0 else "down", "reasons": list(t.reasons[j]),
                    "run_id": hs.run.run_id, "run_time": iso_time(hs.run.run_time),
                    "map_url": (f"/runs/{map_run}?km_from={max(lo - 0.1, 0.0):.3f}&km_to={hi + 0.1:.3f}"
                                if map_run is not None else None),
                })
    items.sort(key=lambda x: (-x["priority"], x["line_id"], x["track"], x["km_from"]))
    total = len(items)
    items = items[: q.limit]
    for rank, item in enumerate(items, start=1):
        item["rank"] = rank
    return total, items, {ln.id: ln for ln in chosen}


def hotspots(db: Database, settings: Settings, q: HotspotQuery) -> dict:
    """Segments of every line's newest run (or one line's), ranked by priority (docs/condition.md)."""
    total, items, _ = _hotspots(db, settings, q)
    return {"segment_m": q.segment_m, "min_priority": q.min_priority, "total": total, "items": items}


#: Columns of the work list as CSV.
HOTSPOT_CSV_COLUMNS = ("rank", "line_id", "track", "km_from", "km_to", "segment_m", "superstructure", "priority",
                       "reasons", "direction", "index", "anomaly_z", "change_pct", "change_z", "rate_pct_per_year",
                       "trend_z", "wheels_agreeing", "n_wheels", "run_id", "run_time")


def hotspots_csv(db: Database, settings: Settings, q: HotspotQuery) -> str:
    """The work list as CSV: one row per segment; ``reasons`` joined by ``+``; km in km, changes in %."""
    _, items, _ = _hotspots(db, settings, q)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(HOTSPOT_CSV_COLUMNS)
    for item in items:
        writer.writerow(["+".join(item[c]) if c == "reasons" else ("" if item[c] is None else item[c])
                         for c in HOTSPOT_CSV_COLUMNS])
    return out.getvalue()


def hotspots_geojson(db: Database, settings: Settings, q: HotspotQuery) -> dict:
    """The work list as a GeoJSON FeatureCollection: the segment's LineString in WGS84 where the
    line's geometry is imported (else null), the work-list fields as properties."""
    _, items, by_key = _hotspots(db, settings, q)
    geoms: dict[int, object] = {}
    with db.read() as session:
        for key, line in by_key.items():
            row = recorder_crud.find_geometry(session, line.line_id, line.track)
            geoms[key] = recorder_crud.to_line_geometry(row) if row is not None else None
    features = []
    for item in items:
        geom = geoms.get(item["line_key"])
        geometry = None
        if geom is not None:
            lon, lat = geom.lonlat_at_km(np.linspace(item["km_from"], item["km_to"], 3))
            geometry = {"type": "LineString", "coordinates": [[float(a), float(b)] for a, b in zip(lon, lat,
                                                                                                  strict=True)]}
        props = {k: v for k, v in item.items() if k not in ("line_key", "map_url")}
        features.append({"type": "Feature", "id": f"{item['line_id']}/{item['track']}/{item['km_from']:.3f}",
                         "geometry": geometry, "properties": props})
    return {"type": "FeatureCollection", "features": features}
