"""Maintenance effect, from the segment condition store: what each imported action did to the
condition index over its extent (before, after, recovery, how long it lasted) and the
before/after view of one action. The index is taken relative to the surrounding track of the
same run (:mod:`app.condition.maintenance`), so runs at other speeds compare. The paper's correlation of amplitude with the number of
actions stays at ``GET /analytics/maintenance``."""

from __future__ import annotations

import datetime as dt
import math
from typing import Annotated

import numpy as np
from fastapi import APIRouter, Path, Query
from pydantic import BaseModel, Field

from app.analysis.condition.maintenance_effect import ActionEffect, action_effect
from app.api.condition import LineIdQ, TrackQ, check_line_km, resolve_line
from app.api.deps import DbDep, check_km, km_query
from app.api.errors import ApiError, not_found
from app.api.reference import parse_types
from app.condition.maintenance import extent_profile, extent_series
from app.condition.writer import days_of
from app.db import reference_crud
from app.db.models import ConditionLine, MaintenanceAction
from app.db.session import Database

__all__ = ["router"]

router = APIRouter(prefix="/condition", tags=["condition"])

BeforeQ = Annotated[float, Query(gt=0, le=3650, description="days before the action compared")]
AfterQ = Annotated[float, Query(gt=0, le=3650, description="days just after the action compared")]
RegainQ = Annotated[float, Query(gt=0, le=1, description="fraction of the recovery whose loss ends the effect")]
_MARGIN_KM = 0.1


class EffectOut(BaseModel):
    action_id: int
    line_id: str
    track: str
    type: str
    date: str
    km_from: float
    km_to: float
    n_runs: int = Field(description="runs of the line over the action's extent (0: no before/after view)")
    n_runs_before: int
    n_runs_after: int
    index_before: float | None = Field(description="median index over the extent before, relative to the "
                                                   "surrounding track of each run (log units)")
    index_after: float | None = Field(description="the same just after")
    recovery: float | None = Field(description="after minus before (negative: lower index, e.g. amplitude)")
    recovery_pct: float | None = Field(description="the recovery as a percentage of the amplitude")
    slope_after_per_year: float | None = Field(description="index change per year after the action")
    lasted_days_observed: float | None = Field(description="days until the given fraction of the recovery was lost")
    lasted_days_projected: float | None = Field(description="the same projected from the slope after")


class EffectsOut(BaseModel):
    regain_fraction: float
    items: list[EffectOut]


class SeriesPoint(BaseModel):
    run_id: int
    start_time: str
    index: float


class EffectDetailOut(EffectOut):
    series: list[SeriesPoint] = Field(description="index over the extent per run relative to its surroundings, "
                                              "oldest first")
    profile_km: list[float] = Field(description="segment starts (km) of the extent ± 100 m")
    profile_before: list[float | None] = Field(description="mean relative index per segment over the runs before")
    profile_after: list[float | None] = Field(description="mean index per segment over the runs just after")


def _effect_of(db: Database, line: ConditionLine, a: MaintenanceAction, *, before_days: float, after_days: float,
               regain: float) -> tuple[ActionEffect, list, np.ndarray]:
    with db.read() as session:
        runs, values = extent_series(session, line, a.km_from, a.km_to)
    day = days_of(dt.datetime.combine(a.date, dt.time(12, 0), tzinfo=dt.UTC))
    days = np.array([days_of(r.run_time) for r in runs])
    effect = action_effect(days, values, day, before_days=before_days, after_days=after_days,
                           regain_fraction=regain)
    return effect, runs, values


def _out(a: MaintenanceAction, line: ConditionLine, e: ActionEffect, n_runs: int) -> dict:
    return {
        "action_id": a.id, "line_id": line.line_id, "track": line.track, "type": a.type, "date": a.date.isoformat(),
        "km_from": a.km_from, "km_to": a.km_to, "n_runs": n_runs, "n_runs_before": e.n_before, "n_runs_after": e.n_after,
        "index_before": e.index_before, "index_after": e.index_after, "recovery": e.recovery,
        "recovery_pct": 100.0 * math.expm1(e.recovery) if e.recovery is not None else None,
        "slope_after_per_year": e.slope_after_per_year, "lasted_days_observed": e.lasted_days_observed,
        "lasted_days_projected": e.lasted_days_projected,
    }


@router.get("/maintenance-effect", response_model=EffectsOut, summary="Effect of each maintenance action")
def maintenance_effects(
    db: DbDep, line_id: LineIdQ, track: TrackQ = None,
    type: Annotated[str | None, Query(description="comma-separated action types")] = None,
    since: Annotated[dt.date | None, Query(description="actions on or after this date")] = None,
    km_from: Annotated[float | None, km_query("Lower km bound")] = None,
    km_to: Annotated[float | None, km_query("Upper km bound")] = None,
    before_days: BeforeQ = 90.0, after_days: AfterQ = 30.0, regain_fraction: RegainQ = 0.5,
) -> dict:
    """Every imported action of the line (filtered by type, date, km): the index over its extent
    before and after, the recovery, the slope after and how long the recovery lasted."""
    types = parse_types(type)
    check_km(km_from, km_to)
    line = resolve_line(db, line_id, track)
    check_line_km(line, km_from=km_from, km_to=km_to)
    with db.read() as session:
        actions = reference_crud.reference_frame(session, "maintenance", line_id=line.line_id, track=line.track,
                                                 km_from=km_from, km_to=km_to, types=types, since=since)
        rows = [session.get(MaintenanceAction, int(i)) for i in actions["id"]]
    items = []
    for a in sorted(rows, key=lambda r: (r.date, r.km_from)):
        effect, runs, _ = _effect_of(db, line, a, before_days=before_days, after_days=after_days, regain=regain_fraction)
        items.append(_out(a, line, effect, len(runs)))
    return {"regain_fraction": regain_fraction, "items": items}


@router.get("/maintenance-effect/{action_id}", response_model=EffectDetailOut,
            summary="Before/after view of one maintenance action")
def maintenance_effect(
    db: DbDep, action_id: Annotated[int, Path(ge=1, le=2**31 - 1)],
    before_days: BeforeQ = 90.0, after_days: AfterQ = 30.0, regain_fraction: RegainQ = 0.5,
) -> dict:
    """The action's effect, the index over its extent per run, and the index along km (extent
    ± 100 m) averaged over the runs before and the runs just after."""
    with db.read() as session:
        a = session.get(MaintenanceAction, action_id)
    if a is None:
        raise not_found("action", action_id)
    line = resolve_line(db, a.line_id, a.track)
    effect, runs, values = _effect_of(db, line, a, before_days=before_days, after_days=after_days,
                                      regain=regain_fraction)
    day = days_of(dt.datetime.combine(a.date, dt.time(12, 0), tzinfo=dt.UTC))
    days = np.array([days_of(r.run_time) for r in runs])
    before = [r.run_id for r, d in zip(runs, days, strict=True) if day - before_days <= d < day]
    after = [r.run_id for r, d in zip(runs, days, strict=True) if day < d <= day + after_days]
    lo, hi = min(a.km_from, a.km_to) - _MARGIN_KM, max(a.km_from, a.km_to) + _MARGIN_KM
    with db.read() as session:
        km_b, v_b = extent_profile(session, before, lo, hi, action_km=(a.km_from, a.km_to))
        km_a, v_a = extent_profile(session, after, lo, hi, action_km=(a.km_from, a.km_to))
    km = np.union1d(np.round(km_b, 6), np.round(km_a, 6))

    def on(kms: np.ndarray, vals: np.ndarray) -> list[float | None]:
        lookup = dict(zip(np.round(kms, 6).tolist(), vals.tolist(), strict=True))
        return [lookup.get(k) for k in km.tolist()]

    if not runs:
        raise ApiError(409, "action_id", f"no run of line {line.line_id!r} covers action {action_id}")
    return {
        **_out(a, line, effect, len(runs)),
        "series": [{"run_id": r.run_id, "start_time": r.run_time.isoformat(), "index": float(v)}
                   for r, v in zip(runs, values, strict=True)],
        "profile_km": km.tolist(), "profile_before": on(km_b, v_b), "profile_after": on(km_a, v_a),
    }
