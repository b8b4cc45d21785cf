"""Rail findings of a line: its runs' track impacts (dipped welds, joints) followed over the runs.

A track impact is a rail feature, not a support defect: the condition store keeps it out of every
graded row (:func:`app.condition.writer.impact_masks`) and reports it here instead, never as a place.
Per run of the line in the store: its track impacts (the job's ``meta["track_impacts"]``: position,
dip length and depth; a job processed before they were kept, or by the fan-out tasks, has them in the
profile's ``track_impact_mm`` rows, :mod:`app.profiles.impacts`, without a length) moved onto the line's
km axis by the run's alignment shift, and the stretch it covered (its 10 m rows, widened to its own
impacts); :func:`app.analysis.impacts.findings.follow_findings` follows them over the runs, with the
asset register's kind where an asset lies on the finding. A finding's depth trend is read over its sightings
since the latest work on the rails' surface over it that the line's maintenance records hold (grinding, rail
renewal: :func:`app.condition.actions.rail_surface_interventions`), and says since when
(``depth_trend_since``, ``depth_trend_runs``).

A finding's id is ``{first run id}-{its first position on the line in dm}``: fixed by the run that
found it first, so a later run never changes an existing id. ``GET /condition/rail-findings``
(``.csv``), ``GET /condition/rail-findings/{id}`` (its sightings); an unknown id answers 404 naming
it, an unknown ``type`` 422 listing the types.
"""

from __future__ import annotations

import datetime as dt
import math
import re
from collections.abc import Sequence
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.analysis.impacts.findings import (
    FINDING_KINDS,
    RailFinding,
    RunImpacts,
    follow_findings,
    run_coverage,
)
from app.condition import readers as reader
from app.condition.actions import days_of, rail_surface_interventions
from app.condition.lines import resolve_line
from app.core.csv_export import csv_text
from app.core.errors import ApiError
from app.core.i18n import _
from app.core.jsonable import finite_or_none, iso_time
from app.db import assets_crud
from app.db.models import ConditionLine, ConditionRun, Job, SegmentCondition
from app.db.session import Database
from app.db.track_impacts import track_impact_bins
from app.profiles.impacts import group_impacts

__all__ = ["FINDING_TYPES", "CSV_COLUMNS", "check_types", "line_findings", "finding", "findings_csv",
           "finding_id"]

#: The finding types a filter may name.
FINDING_TYPES: tuple[str, ...] = FINDING_KINDS
#: The columns of the CSV (one row per finding).
CSV_COLUMNS: tuple[str, ...] = ("id", "line_id", "track", "type", "km", "depth_mm", "length_m", "runs_seen",
                                "runs_passed", "steady", "first_seen", "last_seen", "depth_trend_mm_per_year",
                                "depth_trend_significant", "depth_trend_since", "asset_type", "asset_name")
_ID = re.compile(r"^([1-9][0-9]{0,9})-(-?[0-9]{1,9})$")
#: The store's row length taken for a run's covered stretch, m.
_COVER_SEG_M = 10


def check_types(types: Sequence[str] | None) -> tuple[str, ...]:
    """The type filter checked: 422 naming ``type`` and listing the types when one is unknown."""
    out = tuple(dict.fromkeys(t.strip() for t in (types or ()) if t.strip()))
    unknown = [t for t in out if t not in FINDING_TYPES]
    if unknown:
        raise ApiError(422, "type", _("unknown finding type(s) {types}: must be one of {known}",
                                      types=", ".join(repr(t) for t in unknown), known=", ".join(FINDING_TYPES)))
    return out


def finding_id(f: RailFinding) -> str:
    """The finding's stable id: its first run and first position on the line (dm)."""
    return f"{f.first_run_id}-{int(round(f.anchor_m * 10.0))}"


def _day(t: dt.datetime, t0: dt.datetime) -> float:
    return (t - t0).total_seconds() / 86400.0


def _surface_work(session: Session, line: ConditionLine, t0: dt.datetime) -> list[tuple[float, float, float]]:
    """The line's recorded work on the rails' surface as ``(start_m, end_m, day)``, days since ``t0`` (a run time:
    timezone-aware, as the store's ``UTCDateTime`` gives it)."""
    start, end, day = rail_surface_interventions(session, line.line_id, line.track)
    origin = days_of(t0)
    return [(float(a), float(b), float(d) - origin) for a, b, d in zip(start, end, day, strict=True)]


def _run_impacts(session: Session, run: ConditionRun, t0: dt.datetime) -> RunImpacts:
    """One run's track impacts on the line's km axis and the stretch it covered."""
    job = session.get(Job, run.job_id)
    kept = job.meta.get("track_impacts") if job is not None and isinstance(job.meta, dict) else None
    if kept is not None:
        impacts = [(float(i["track_m"]) + run.shift_m, float(i["depth_mm"]), float(i.get("length_m", math.nan)))
                   for i in kept]
    else:
        impacts = [(1000.0 * g["km"] + run.shift_m, float(g["depth_mm"]), math.nan)
                   for g in group_impacts(track_impact_bins(session, run.job_id))]
    lo, hi = session.execute(select(func.min(SegmentCondition.seg), func.max(SegmentCondition.seg)).where(
        SegmentCondition.run_id == run.run_id, SegmentCondition.seg_m == _COVER_SEG_M)).one()
    rows = None if lo is None else (float(lo) * _COVER_SEG_M, float(hi + 1) * _COVER_SEG_M)
    covered, inside = run_coverage(impacts, rows)
    return RunImpacts(run.run_id, _day(run.run_time, t0), covered, inside)


def _follow(session: Session, line: ConditionLine) -> tuple[list[RailFinding], dict[int, dt.datetime], dt.datetime | None]:
    """The line's findings, its runs' times and the time the findings' days count from (None: no runs)."""
    runs = reader.line_runs(session, line.id)
    if not runs:
        return [], {}, None
    t0 = runs[0].run_time
    per_run = [_run_impacts(session, r, t0) for r in runs]
    assets = [{"type": a.type, "track_m": 1000.0 * a.km, "name": a.name}
              for a in assets_crud.line_assets(session, line.line_id, line.track)]
    times = {r.run_id: r.run_time for r in runs}
    found = follow_findings([r for r in per_run if all(map(math.isfinite, r.covered_m))], assets=assets,
                            surface_work=_surface_work(session, line, t0))
    return found, times, t0


def _item(line: ConditionLine, f: RailFinding, times: dict[int, dt.datetime], t0: dt.datetime | None) -> dict[str, Any]:
    trend = f.depth_trend()
    since = None
    if t0 is not None and math.isfinite(f.surface_day):
        since = (t0 + dt.timedelta(days=f.surface_day)).date().isoformat()
    asset = None if f.asset is None else {"type": f.asset["type"], "km": float(f.asset["track_m"]) / 1000.0,  # type: ignore[arg-type]
                                          "name": f.asset.get("name")}
    return {
        "id": finding_id(f), "line_id": line.line_id, "track": line.track, "type": f.kind,
        "km": round(f.track_m / 1000.0, 6), "depth_mm": finite_or_none(round(f.depth_mm, 4)),
        "length_m": finite_or_none(f.length_m), "runs_seen": f.runs_seen, "runs_passed": f.runs_passed,
        "steady": f.steady,
        "first_seen": iso_time(times.get(f.sightings[0].run_id)),
        "last_seen": iso_time(times.get(f.sightings[-1].run_id)),
        "depth_trend_mm_per_year": finite_or_none(trend.rate_per_year),
        "depth_trend_se_mm_per_year": finite_or_none(trend.se_per_year),
        "depth_trend_significant": bool(trend.significant),
        "depth_trend_since": since, "depth_trend_runs": len(f.trend_sightings),
        "asset": asset,
    }


def line_findings(db: Database, line_id: str, track: str | None, types: Sequence[str] | None = None, *,
                  steady_only: bool = False) -> dict:
    """The rail findings of a line and track, ascending km (``GET /condition/rail-findings``); 404 naming
    ``line_id`` without runs in the store, 422 naming ``type`` for an unknown type. ``steady_only``: only
    those seen by at least half the runs that passed them (:attr:`RailFinding.steady`); ``unsteady``: how
    many of the type filter's findings that leaves out."""
    wanted = check_types(types)
    line = resolve_line(db, line_id, track)
    with db.read() as session:
        found, times, t0 = _follow(session, line)
    typed = [f for f in found if not wanted or f.kind in wanted]
    items = [_item(line, f, times, t0) for f in typed if f.steady or not steady_only]
    return {"line_id": line.line_id, "track": line.track, "types": list(wanted) or list(FINDING_TYPES),
            "runs": len(times), "steady_only": bool(steady_only),
            "unsteady": sum(1 for f in typed if not f.steady), "items": items}


def finding(db: Database, ident: str) -> dict:
    """One rail finding with its sightings (``GET /condition/rail-findings/{id}``); 404 naming it."""
    missing = ApiError(404, "finding_id", _("rail finding {ident} not found", ident=repr(ident)))
    m = _ID.match(ident)
    if m is None:
        raise missing
    with db.read() as session:
        first = session.get(ConditionRun, int(m.group(1)))
        line = session.get(ConditionLine, first.line_key) if first is not None else None
        if line is None:
            raise missing
        found, times, t0 = _follow(session, line)
    f = next((f for f in found if finding_id(f) == ident), None)
    if f is None:
        raise missing
    out = _item(line, f, times, t0)
    out["sightings"] = [{"run_id": s.run_id, "run_time": iso_time(times.get(s.run_id)),
                         "km": round(s.track_m / 1000.0, 6), "depth_mm": finite_or_none(round(s.depth_mm, 4)),
                         "length_m": finite_or_none(s.length_m)} for s in f.sightings]
    out["passed_run_ids"] = list(f.passed)
    return out


def findings_csv(db: Database, line_id: str, track: str | None, types: Sequence[str] | None = None,
                 lang: str | None = None, *, steady_only: bool = False) -> str:
    """The rail findings as CSV (:data:`CSV_COLUMNS`, one row per finding), written by
    :mod:`app.core.csv_export` (an asset name a spreadsheet would run as a formula is defused); the
    header is the field names, or given ``lang`` the columns' labels and units in it."""
    rows = []
    for item in line_findings(db, line_id, track, types, steady_only=steady_only)["items"]:
        asset = item["asset"] or {}
        row = {**item, "asset_type": asset.get("type"), "asset_name": asset.get("name")}
        rows.append([row.get(c) for c in CSV_COLUMNS])
    return csv_text(CSV_COLUMNS, rows, lang)
