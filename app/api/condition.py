"""Track condition over time, from the segment condition store (never the 25 cm rows).

``GET /condition/lines`` — the lines and tracks of the store;
``GET /condition/heatmap`` — index per run × segment, flagged cells marked;
``GET /condition/trend`` — one segment over every run, with maintenance actions;
``GET /condition/changes`` and ``GET /condition/runs/{id}/changes`` — the change
list (flags) of a line's newest run or of any run; ``GET /condition/flags`` — the
feed of flags for data systems, ``since=`` the last id seen; ``GET /condition/hotspots``
(``.csv``, ``.geojson``) — the work list: segments ranked by where to act first.

A line id (and track) without runs in the store answers 404 naming
``line_id``; a km outside the stored extent of the line answers 422 naming the
km parameter; ``segment_m`` is 10 or 100.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from fastapi import APIRouter, Depends, Query
from fastapi.responses import JSONResponse, Response
from sqlalchemy import select

from app.api.deps import DbDep, RunId, SettingsDep, check_km, km_query, parse_time_range
from app.api.errors import ApiError, not_found
from app.api.schemas.condition import (
    ChangesOut,
    ConditionLinesOut,
    FlagFeedOut,
    HeatmapOut,
    HotspotsOut,
    TrendOut,
)
from app.condition import readers as reader
from app.condition.config import ConditionConfig
from app.condition.fleet import FLEET_SOURCE_FORMAT
from app.condition.hotspots import line_hotspots
from app.condition.index import index_name
from app.condition.maintenance import run_levels
from app.core.config import Settings
from app.db import recorder_crud, reference_crud
from app.db.models import ConditionFlag, ConditionLine, ConditionRun, Job, JobStatus, Run
from app.db.session import Database

__all__ = ["router", "resolve_line", "check_line_km", "segment_length"]

router = APIRouter(prefix="/condition", tags=["condition"])

LineIdQ = Annotated[str, Query(min_length=1, max_length=128, description="Line id")]
TrackQ = Annotated[str | None, Query(max_length=64, description="Track (default: the line's only track)")]
SegmentQ = Annotated[int, Query(description="segment length, m: 10 or 100")]
WheelQ = Annotated[str | None, Query(pattern=r"^[0-9A-Za-z]{1,8}$", description="wheel (default: mean over wheels)")]
_SEGMENTS = (10, 100)
_WHEELS = ("11", "12", "41", "42")
_MAX_FEED = 1000


def segment_length(value: int) -> int:
    """``segment_m`` checked: 10 or 100 (422 otherwise)."""
    if value not in _SEGMENTS:
        raise ApiError(422, "segment_m", f"must be 10 or 100, got {value}")
    return value


def _wheel(w: str | None) -> str | None:
    if w is None:
        return None
    w = w[1:] if w[:1] in ("Z", "z") else w
    if w not in _WHEELS:
        raise ApiError(422, "wheel", f"must be one of {', '.join(_WHEELS)} (or Z11 …), got {w!r}")
    return w


def resolve_line(db: Database, line_id: str, track: str | None) -> ConditionLine:
    """The store's line; 404 naming ``line_id`` when it has no runs there, 422 when the track is ambiguous."""
    with db.read() as session:
        lines = reader.find_lines(session, line_id, track)
    if not lines:
        where = f"line {line_id!r}" + (f" track {track!r}" if track is not None else "")
        raise ApiError(404, "line_id", f"{where} has no runs in the condition store")
    if len(lines) > 1:
        raise ApiError(422, "track", f"line {line_id!r} has tracks {', '.join(repr(x.track) for x in lines)}: choose one")
    return lines[0]


def check_line_km(line: ConditionLine, **values: float | None) -> None:
    """422 naming the parameter when a km lies outside the line's stored extent."""
    if line.km_min is None or line.km_max is None:
        return
    for name, value in values.items():
        if value is None:
            continue
        if not math.isfinite(value) or value < line.km_min - 1e-9 or value > line.km_max + 1e-9:
            raise ApiError(422, name, f"km {value} is outside line {line.line_id!r} track {line.track!r} "
                                      f"(km {line.km_min:.3f}–{line.km_max:.3f})")


def _num(v: float | None) -> float | None:
    return float(v) if v is not None and math.isfinite(float(v)) else None


@router.get("/lines", response_model=ConditionLinesOut, summary="Lines and tracks of the condition store")
def lines(db: DbDep) -> dict:
    with db.read() as session:
        items = reader.list_lines(session)
    return {"items": [{
        "line_id": s.line.line_id, "track": s.line.track, "km_min": s.line.km_min, "km_max": s.line.km_max,
        "n_runs": s.n_runs, "first_run": reader.iso_time(s.first_run), "last_run": reader.iso_time(s.last_run),
        "last_run_id": s.last_run_id, "last_run_flags": s.last_run_flags, "reference_run_id": s.line.ref_run_id,
    } for s in items]}


@router.get("/heatmap", response_model=HeatmapOut, summary="Index per run × segment of a line")
def heatmap(db: DbDep, line_id: LineIdQ, track: TrackQ = None, segment_m: SegmentQ = 100, wheel: WheelQ = None,
            km_from: Annotated[float | None, km_query("Lower km bound")] = None,
            km_to: Annotated[float | None, km_query("Upper km bound")] = None,
            date_from: Annotated[str | None, Query(description="ISO date or datetime")] = None,
            date_to: Annotated[str | None, Query(description="ISO date or datetime")] = None) -> dict:
    """Rows are the line's runs (oldest first), columns its segments; the index of the wheel
    asked for, or the mean over the wheels. ``flagged`` marks cells holding a flag of the run."""
    seg_m = segment_length(segment_m)
    w = _wheel(wheel)
    check_km(km_from, km_to)
    start, end = parse_time_range(date_from, date_to, ("date_from", "date_to"), whole_days=True)
    line = resolve_line(db, line_id, track)
    check_line_km(line, km_from=km_from, km_to=km_to)
    with db.read() as session:
        runs = reader.line_runs(session, line.id, start, end)
        hm = reader.heatmap(session, runs, seg_m, wheel=w, km_from=km_from, km_to=km_to)
        name = index_name(session, line.line_id, line.track)
    matrix = np.where(np.isfinite(hm.matrix), np.round(hm.matrix, 5), np.nan)
    return {
        "line_id": line.line_id, "track": line.track, "segment_m": seg_m, "wheel": w, "index": name,
        "km": (hm.seg * seg_m / 1000.0).tolist(),
        "runs": [{"run_id": r.run_id, "start_time": reader.iso_time(r.run_time), "shift_m": r.shift_m, "n_flags": r.n_flags}
                 for r in hm.runs],
        "matrix": [[None if math.isnan(v) else v for v in row] for row in matrix.tolist()],
        "flagged": [list(c) for c in hm.flagged],
    }


@router.get("/trend", response_model=TrendOut, summary="One segment over every run of a line")
def trend(db: DbDep, line_id: LineIdQ, km: Annotated[float, km_query("A km inside the segment")],
          track: TrackQ = None, segment_m: SegmentQ = 10, wheel: WheelQ = None) -> dict:
    """Per run (oldest first) the segment's index (mean over the wheels), the same relative to
    the surrounding track of the run (±1 km: what the run's speed and level share cancels) and
    each wheel's row, with the maintenance actions that cover the segment."""
    seg_m = segment_length(segment_m)
    w = _wheel(wheel)
    line = resolve_line(db, line_id, track)
    check_line_km(line, km=km)
    seg = int(math.floor(km * 1000.0 / seg_m))
    lo, hi = seg * seg_m / 1000.0, (seg + 1) * seg_m / 1000.0
    with db.read() as session:
        history = reader.segment_history(session, line.id, seg_m, seg, w)
        flagged = set(session.scalars(select(ConditionFlag.run_id).where(
            ConditionFlag.line_key == line.id, ConditionFlag.seg_m == seg_m, ConditionFlag.seg == seg)))
        actions = reference_crud.reference_frame(session, "maintenance", line_id=line.line_id, track=line.track,
                                                 km_from=lo, km_to=hi)
        levels = run_levels(session, [run.run_id for run, _ in history], lo, hi)
    points = []
    for run, rows in history:
        idx = [r.index for r in rows if r.index is not None]
        mean = float(np.mean(idx)) if idx else None
        level = levels.get(run.run_id)
        points.append({
            "run_id": run.run_id, "start_time": reader.iso_time(run.run_time), "index": mean,
            "relative": mean - level if mean is not None and level is not None else None,
            "flagged": run.run_id in flagged,
            "wheels": [{
                "wheel": r.wheel, "index": float(r.index), "index_sd": _num(r.index_sd), "amp_mean": float(r.amp_mean),
                "amp_p95": float(r.amp_p95), "speed_kmh": float(r.speed_mean) * 3.6, "n_valid": r.n_valid,
                "n_history": r.n_history, "change": _num(r.change), "change_z": _num(r.change_z),
                "trend_rate_per_year": _num(r.trend_rate), "trend_z": _num(r.trend_z),
            } for r in rows],
        })
    return {
        "line_id": line.line_id, "track": line.track, "segment_m": seg_m, "segment_km": [lo, hi], "points": points,
        "maintenance": [{"id": int(a.id), "type": a.type, "date": a.date.isoformat(), "km_from": float(a.km_from),
                         "km_to": float(a.km_to)} for a in actions.itertuples()],
    }


def _changes(db: Database, run: ConditionRun) -> dict:
    with db.read() as session:
        line = session.get(ConditionLine, run.line_key)
        flags = reader.run_flags(session, run.run_id)
        job = session.get(Job, run.job_id)  # its condition summary: provenance
    summary = ((job.meta or {}).get("condition") or {}) if job is not None else {}
    return {
        "run_id": run.run_id, "line_id": line.line_id, "track": line.track, "start_time": reader.iso_time(run.run_time),
        "shift_m": run.shift_m, "history_runs": summary.get("history_runs"),
        "items": [reader.flag_dict(f, line) for f in flags],
    }


@router.get("/changes", response_model=ChangesOut, summary="Change list of a line's newest run")
def newest_changes(db: DbDep, line_id: LineIdQ, track: TrackQ = None) -> dict:
    """The flags of the line's newest run in the store, strongest first."""
    line = resolve_line(db, line_id, track)
    with db.read() as session:
        run = reader.newest_run(session, line.id)
    if run is None:
        raise ApiError(404, "line_id", f"line {line_id!r} has no runs in the condition store")
    return _changes(db, run)


@router.get("/runs/{run_id}/changes", response_model=ChangesOut, summary="Change list of a run")
def run_changes(db: DbDep, run_id: RunId) -> dict:
    """The flags of a run, strongest first; 404 when the run has no rows in the store."""
    with db.read() as session:
        run = session.get(ConditionRun, run_id)
    if run is None:
        raise not_found("run", run_id)
    return _changes(db, run)


@router.get("/flags", response_model=FlagFeedOut, summary="Feed of condition flags (poll with since=)")
def flags(db: DbDep, since: Annotated[int, Query(ge=0, le=2**62, description="last flag id seen (0: from the start)")] = 0,
          limit: Annotated[int, Query(ge=1, le=_MAX_FEED)] = 200, line_id: str | None = None, track: TrackQ = None,
          new_only: Annotated[bool, Query(description="only flags new in their run")] = False) -> dict:
    """Flags with an id above ``since``, ascending. Ids grow in the order the flags become
    visible, so a system that keeps the last id it saw (``next_since``) never misses one; the
    flags of a reprocessed run are replaced (new ids)."""
    keys = None
    if line_id is not None:
        keys = [resolve_line(db, line_id, track).id]
    with db.read() as session:
        items = reader.flags_since(session, since, limit, line_keys=keys, only_new=new_only)
        lines_ = {ln.id: ln for ln in session.scalars(
            select(ConditionLine).where(ConditionLine.id.in_({f.line_key for f in items})))}
    return {"items": [reader.flag_dict(f, lines_[f.line_key]) for f in items],
            "next_since": items[-1].id if items else since}


# --- hotspots: the work list ---------------------------------------------------------------
@dataclass(frozen=True)
class _HotspotQuery:
    """Filters of the work list (JSON, CSV and GeoJSON alike)."""

    line_id: str | None
    track: str | None
    km_from: float | None
    km_to: float | None
    superstructure: str | None
    segment_m: int
    min_priority: float
    limit: int


def _hotspot_query(
    line_id: Annotated[str | None, Query(min_length=1, max_length=128, description="Line id (default: every line)")] = None,
    track: TrackQ = None,
    km_from: Annotated[float | None, km_query("Lower km bound (needs line_id)")] = None,
    km_to: Annotated[float | None, km_query("Upper km bound (needs line_id)")] = None,
    superstructure: Annotated[str | None, Query(alias="class", max_length=64,
                                                description="superstructure class ('' = outside the sections)")] = None,
    segment_m: SegmentQ = 10,
    min_priority: Annotated[float, Query(ge=0, le=1000, description="least priority listed (1: beyond a threshold)")] = 1.0,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 200,
) -> _HotspotQuery:
    return _HotspotQuery(line_id, track, km_from, km_to, superstructure, segment_length(segment_m), min_priority, limit)


HotspotQ = Annotated[_HotspotQuery, Depends(_hotspot_query)]


def _map_run(session, line: ConditionLine) -> int | None:
    """The line's newest run whose 25 cm rows are there (what the stiffness map shows)."""
    return session.scalar(
        select(Run.id).where(Run.line_id == line.line_id, Run.track == line.track,
                             Run.source_format != FLEET_SOURCE_FORMAT,
                             select(Job.id).where(Job.run_id == Run.id, Job.status == JobStatus.DONE).exists())
        .order_by(Run.start_time.desc(), Run.id.desc()).limit(1))


def _hotspots(db: Database, settings: Settings, q: _HotspotQuery) -> tuple[int, list[dict], dict[int, ConditionLine]]:
    """(matching count, items ranked by priority, lines by key)."""
    check_km(q.km_from, q.km_to)
    if q.line_id is not None:
        lines = [resolve_line(db, q.line_id, q.track)]
        check_line_km(lines[0], km_from=q.km_from, km_to=q.km_to)
    else:
        if q.km_from is not None or q.km_to is not None:
            raise ApiError(422, "line_id", "is required with km_from / km_to")
        with db.read() as session:
            lines = [s.line for s in reader.list_lines(session)
                     if q.track is None or s.line.track == q.track]
    params = ConditionConfig.from_settings(settings).change
    items = []
    with db.read() as session:
        for line in lines:
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
                change, rate = _num(t.change[j]), _num(t.rate_per_year[j])
                items.append({
                    "line_key": line.id, "line_id": line.line_id, "track": line.track, "km_from": lo, "km_to": hi,
                    "segment_m": q.segment_m, "superstructure": str(hs.classes[j]), "index": _num(t.index[j]),
                    "anomaly_z": _num(t.anomaly_z[j]), "change": change,
                    "change_pct": 100.0 * math.expm1(change) if change is not None else None,
                    "change_z": _num(t.change_z[j]), "rate_per_year": rate,
                    "rate_pct_per_year": 100.0 * math.expm1(rate) if rate is not None else None,
                    "trend_z": _num(t.trend_z[j]), "wheels_agreeing": int(t.agreeing[j]),
                    "n_wheels": int(t.n_wheels[j]), "priority": float(t.priority[j]),
                    "direction": "up" if t.direction[j] > 0 else "down", "reasons": list(t.reasons[j]),
                    "run_id": hs.run.run_id, "run_time": reader.iso_time(hs.run.run_time),
                    "map_url": (f"/runs/{map_run}?km_from={max(lo - 0.1, 0.0):.3f}&km_to={hi + 0.1:.3f}"
                                if map_run is not None else None),
                })
    items.sort(key=lambda x: (-x["priority"], x["line_id"], x["track"], x["km_from"]))
    total = len(items)
    items = items[: q.limit]
    for rank, item in enumerate(items, start=1):
        item["rank"] = rank
    return total, items, {ln.id: ln for ln in lines}


@router.get("/hotspots", response_model=HotspotsOut, summary="Work list: segments ranked by where to act first")
def hotspots(db: DbDep, settings: SettingsDep, q: HotspotQ) -> dict:
    """Segments of every line's newest run (or one line's), ranked by priority: the anomaly of
    the segment's index against its superstructure class, the change against its history, the
    trend per year and the wheels agreeing (docs/condition.md). Filter by line, track, km and class."""
    total, items, _ = _hotspots(db, settings, q)
    return {"segment_m": q.segment_m, "min_priority": q.min_priority, "total": total, "items": items}


_CSV_COLUMNS = ("rank", "line_id", "track", "km_from", "km_to", "segment_m", "superstructure", "priority", "reasons",
                "direction", "index", "anomaly_z", "change_pct", "change_z", "rate_pct_per_year", "trend_z",
                "wheels_agreeing", "n_wheels", "run_id", "run_time")


@router.get("/hotspots.csv", summary="Work list as CSV (the filters of /condition/hotspots)",
            response_class=Response, responses={200: {"content": {"text/csv": {}}}})
def hotspots_csv(db: DbDep, settings: SettingsDep, q: HotspotQ) -> Response:
    """One row per segment; ``reasons`` joined by ``+``; km in km, changes in %."""
    _, items, _ = _hotspots(db, settings, q)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(_CSV_COLUMNS)
    for item in items:
        writer.writerow(["+".join(item[c]) if c == "reasons" else ("" if item[c] is None else item[c])
                         for c in _CSV_COLUMNS])
    return Response(out.getvalue(), media_type="text/csv",
                    headers={"Content-Disposition": 'attachment; filename="hotspots.csv"'})


@router.get("/hotspots.geojson", summary="Work list as GeoJSON (the filters of /condition/hotspots)",
            response_class=JSONResponse, responses={200: {"content": {"application/geo+json": {}}}})
def hotspots_geojson(db: DbDep, settings: SettingsDep, q: HotspotQ) -> JSONResponse:
    """A FeatureCollection, one feature per segment with the work-list fields as properties
    (line, track, km: linear referencing). Where a line geometry is imported
    (``/geometry``) the geometry is the segment's LineString in WGS84, else null."""
    _, items, lines = _hotspots(db, settings, q)
    geoms: dict[int, object] = {}
    with db.read() as session:
        for key, line in lines.items():
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
    return JSONResponse({"type": "FeatureCollection", "features": features},
                        media_type="application/geo+json")
