"""What maintenance did: the condition index over an action's extent, run by run, against the track
around it, before and after the action's day (``GET /condition/maintenance-effect``).

One rule reads an extent against its surroundings
(:func:`app.condition.readers.extent_readings` → :func:`~app.analysis.condition.extent_level.extent_level`):
per run the median of the store's 10 m condition index (mean over the wheels) inside the extent minus the
mean within ``effect_around_m`` of its centre outside the extent widened by ``effect_margin_m``
(``TRACKVKF_PLACES_EFFECT_AROUND_M`` / ``_MARGIN_M``). What the whole neighbourhood shares in one run —
the speed the train passed at (``ln A`` is not speed-conditioned), a sensor's calibration, the season —
cancels, and what happened to the extent remains; the median inside keeps the very place the action was
for from dominating it. The effect itself (before, after, recovery, how long it lasted) is
:func:`~app.analysis.condition.maintenance_effect.action_effect`.
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np

from app.analysis.condition import FINE_SEGMENT_M
from app.analysis.condition.maintenance_effect import ActionEffect, action_effect
from app.condition.lines import check_line_km, resolve_line
from app.condition.readers import ExtentReading, extent_readings, line_runs
from app.condition.writer import days_of
from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.db import reference_crud
from app.db.models import ConditionLine, ConditionRun, MaintenanceAction
from app.db.session import Database
from app.places.config import PlacesConfig

__all__ = ["MARGIN_KM", "action_effects", "action_effect_detail"]

#: Margin of the before/after profile around an action's extent, km.
MARGIN_KM = 0.1
#: The store's rows an extent is read from, m (the finest).
_SEG_M = int(FINE_SEGMENT_M)


def _readings(db: Database, line: ConditionLine, a: MaintenanceAction,
              config: PlacesConfig) -> tuple[list[ConditionRun], dict[int, ExtentReading]]:
    """The line's runs reading the action's extent against its surroundings (oldest first) and their readings."""
    with db.read() as session:
        runs = line_runs(session, line.id)
        got = extent_readings(session, [r.run_id for r in runs], a.km_from * 1000.0, a.km_to * 1000.0,
                              around_m=config.effect_around_m, margin_m=config.effect_margin_m, seg_m=_SEG_M)
    runs = [r for r in runs if r.run_id in got and math.isfinite(got[r.run_id].level)]
    return runs, got


def _action_day(a: MaintenanceAction) -> float:
    return days_of(dt.datetime.combine(a.date, dt.time(12, 0), tzinfo=dt.UTC))


def _effect(a: MaintenanceAction, runs: list[ConditionRun], got: dict[int, ExtentReading], *, before_days: float,
            after_days: float, regain: float) -> ActionEffect:
    days = np.array([days_of(r.run_time) for r in runs])
    values = np.array([got[r.run_id].level for r in runs])
    return action_effect(days, values, _action_day(a), before_days=before_days, after_days=after_days,
                         regain_fraction=regain)


def _out(a: MaintenanceAction, line: ConditionLine, e: ActionEffect, n_runs: int) -> dict:
    return {
        "action_id": a.id, "line_id": line.line_id, "track": line.track, "type": a.type, "date": a.date.isoformat(),
        "km_from": a.km_from, "km_to": a.km_to, "n_runs": n_runs, "n_runs_before": e.n_before, "n_runs_after": e.n_after,
        "condition_index_before": e.index_before, "condition_index_after": e.index_after, "recovery": e.recovery,
        "recovery_pct": 100.0 * math.expm1(e.recovery) if e.recovery is not None else None,
        "slope_after_per_year": e.slope_after_per_year, "lasted_days_observed": e.lasted_days_observed,
        "lasted_days_projected": e.lasted_days_projected,
    }


def action_effects(db: Database, line_id: str, track: str | None, *, types: list[str] | None,
                   since: dt.date | None, km_from: float | None, km_to: float | None, before_days: float,
                   after_days: float, regain_fraction: float, config: PlacesConfig) -> dict:
    """Every imported action of the line (filtered by type, date, km): the condition index over its extent
    against its surroundings before and after, the recovery, the slope after and how long it lasted."""
    line = resolve_line(db, line_id, track)
    check_line_km(line, km_from=km_from, km_to=km_to)
    with db.read() as session:
        actions = reference_crud.reference_frame(session, "maintenance", line_id=line.line_id, track=line.track,
                                                 km_from=km_from, km_to=km_to, types=types, since=since)
        rows = [session.get(MaintenanceAction, int(i)) for i in actions["id"]]
    items = []
    for a in sorted(rows, key=lambda r: (r.date, r.km_from)):
        runs, got = _readings(db, line, a, config)
        effect = _effect(a, runs, got, before_days=before_days, after_days=after_days, regain=regain_fraction)
        items.append(_out(a, line, effect, len(runs)))
    return {"regain_fraction": regain_fraction, "items": items}


def _profile(got: dict[int, ExtentReading], run_ids: list[int], lo_km: float, hi_km: float) -> dict[float, float]:
    """Per segment start (km, rounded to the mm) of the segments holding ``[lo_km, hi_km]`` (within what was
    read): the mean over ``run_ids`` of the segment's condition index minus the run's surroundings level."""
    a, b = math.floor(lo_km * 1000.0 / _SEG_M), math.floor(hi_km * 1000.0 / _SEG_M)
    sums: dict[float, list[float]] = {}
    for rid in run_ids:
        r = got[rid]
        if not math.isfinite(r.around):
            continue
        keep = (r.seg >= a) & (r.seg <= b) & np.isfinite(r.index)
        km = np.round(r.seg[keep] * _SEG_M / 1000.0, 6)
        for k, v in zip(km.tolist(), (r.index[keep] - r.around).tolist(), strict=True):
            sums.setdefault(k, []).append(v)
    return {k: float(np.mean(v)) for k, v in sums.items()}


def action_effect_detail(db: Database, action_id: int, *, before_days: float, after_days: float,
                         regain_fraction: float, config: PlacesConfig) -> dict:
    """The action's effect, the condition index over its extent per run against its surroundings, and along
    km (extent ± :data:`MARGIN_KM`) each segment against the run's surroundings, averaged over the runs before
    and the runs just after."""
    with db.read() as session:
        a = session.get(MaintenanceAction, action_id)
    if a is None:
        raise not_found("action", action_id)
    line = resolve_line(db, a.line_id, a.track)
    runs, got = _readings(db, line, a, config)
    if not runs:
        raise ApiError(409, "action_id", _("no run of line {line} covers action {action_id}", line=repr(line.line_id),
                                                    action_id=action_id))
    effect = _effect(a, runs, got, before_days=before_days, after_days=after_days, regain=regain_fraction)
    day = _action_day(a)
    days = [days_of(r.run_time) for r in runs]
    before = [r.run_id for r, d in zip(runs, days, strict=True) if day - before_days <= d < day]
    after = [r.run_id for r, d in zip(runs, days, strict=True) if day < d <= day + after_days]
    lo, hi = min(a.km_from, a.km_to) - MARGIN_KM, max(a.km_from, a.km_to) + MARGIN_KM
    prof_b, prof_a = _profile(got, before, lo, hi), _profile(got, after, lo, hi)
    km = sorted(set(prof_b) | set(prof_a))
    return {
        **_out(a, line, effect, len(runs)),
        "series": [{"run_id": r.run_id, "start_time": r.run_time.isoformat(), "condition_index": got[r.run_id].level}
                   for r in runs],
        "profile_km": km, "profile_before": [prof_b.get(k) for k in km], "profile_after": [prof_a.get(k) for k in km],
    }
