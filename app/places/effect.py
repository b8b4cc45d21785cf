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

**One rule, by action type** (issue 33): the surroundings are the track **of the extent's own
superstructure class passed at its speed** (:func:`~app.analysis.condition.extent_level.like_surroundings`,
the matched-speed rule :mod:`app.analysis.speed_match`; a ramp or another class moves with speed
differently), and each run after the action is compared with the runs before it **at its own speed**
(the place's own baseline at that speed): a speed mix in the windows does not set the figure. A tamping
(any action on the support) reports its change as the support's (``support_change`` = ``recovery``); a
grinding or a rail renewal (:data:`~app.analysis.condition.interventions.RAIL_SURFACE_ACTIONS`) reports
the rail surface's response change across the work (``rail_surface_change``) and the support's change
since, against the new surface's own baseline (``support_change``, = ``recovery``; ≈ 0 for a grinding)
apart (:func:`~app.analysis.condition.maintenance_effect.split_effect`). Every answer states its sign
convention (:data:`SIGN_CONVENTION`), its runs (``n_runs_before`` / ``n_runs_after``), the recovery's
1 σ interval (``recovery_low`` / ``recovery_high``, :data:`INTERVAL`) and how long the effect held only
within the runs seen (``followed_days``).
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np

from app.analysis.condition import FINE_SEGMENT_M
from app.analysis.condition.maintenance_effect import (
    ActionEffect,
    SplitEffect,
    action_effect,
    split_effect,
)
from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE
from app.condition.actions import days_of
from app.condition.lines import check_line_km, resolve_line
from app.condition.readers import ExtentReading, extent_readings, line_runs
from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.db import reference_crud
from app.db.models import ConditionLine, ConditionRun, MaintenanceAction
from app.db.places import run_vehicles
from app.db.session import Database
from app.places.config import PlacesConfig
from app.places.index import segment_classes

__all__ = ["MARGIN_KM", "SIGN_CONVENTION", "INTERVAL", "action_effects", "action_effect_detail"]

#: The sign convention every effect answer states.
SIGN_CONVENTION = "after - before, ln units of the amplitude (_pct: 100 * expm1); negative = lower amplitude"
#: What ``recovery_low`` / ``recovery_high`` span.
INTERVAL = "1 sigma (68 %)"

#: Margin of the before/after profile around an action's extent, km.
MARGIN_KM = 0.1
#: The store's rows an extent is read from, m (the finest).
_SEG_M = int(FINE_SEGMENT_M)


def _readings(db: Database, line: ConditionLine, a: MaintenanceAction,
              config: PlacesConfig) -> tuple[list[ConditionRun], dict[int, ExtentReading], dict[int, str | None]]:
    """The line's runs reading the action's extent against its surroundings (oldest first), their readings and
    their vehicles."""
    with db.read() as session:
        runs = line_runs(session, line.id)
        got = extent_readings(session, [r.run_id for r in runs], a.km_from * 1000.0, a.km_to * 1000.0,
                              around_m=config.effect_around_m, margin_m=config.effect_margin_m, seg_m=_SEG_M,
                              speed_tolerance=DEFAULT_SPEED_TOLERANCE,
                              classes=lambda seg: segment_classes(session, line, seg, config.section_margin_m))
        runs = [r for r in runs if r.run_id in got and math.isfinite(got[r.run_id].level)]
        vehicles = run_vehicles(session, [r.run_id for r in runs])
    return runs, got, vehicles


def _action_day(a: MaintenanceAction) -> float:
    return days_of(dt.datetime.combine(a.date, dt.time(12, 0), tzinfo=dt.UTC))


def _effect(a: MaintenanceAction, runs: list[ConditionRun], got: dict[int, ExtentReading],
            vehicle_of: dict[int, str | None], *, before_days: float, after_days: float,
            regain: float) -> tuple[ActionEffect, SplitEffect]:
    days = np.array([days_of(r.run_time) for r in runs])
    values = np.array([got[r.run_id].level for r in runs])
    speeds = np.array([got[r.run_id].speed for r in runs])
    vehicles = np.array([vehicle_of.get(r.run_id) for r in runs], dtype=object)
    day = _action_day(a)
    e = action_effect(days, values, day, before_days=before_days, after_days=after_days, regain_fraction=regain,
                      speeds=speeds, speed_tolerance=DEFAULT_SPEED_TOLERANCE, vehicles=vehicles)
    return e, split_effect(str(a.type), days, values, speeds, day, e, after_days=after_days,
                           speed_tolerance=DEFAULT_SPEED_TOLERANCE, vehicles=vehicles)


def _pct(x: float | None) -> float | None:
    return 100.0 * math.expm1(x) if x is not None else None


def _out(a: MaintenanceAction, line: ConditionLine, effect: tuple[ActionEffect, SplitEffect], n_runs: int) -> dict:
    e, split = effect
    return {
        "action_id": a.id, "line_id": line.line_id, "track": line.track, "type": a.type, "date": a.date.isoformat(),
        "km_from": a.km_from, "km_to": a.km_to, "n_runs": n_runs, "n_runs_before": e.n_before, "n_runs_after": e.n_after,
        "condition_index_before": e.index_before, "condition_index_after": e.index_after,
        "sign_convention": SIGN_CONVENTION, "interval": INTERVAL,
        "recovery": split.support_change, "recovery_pct": _pct(split.support_change),
        "recovery_low": split.support_low, "recovery_high": split.support_high,
        "support_change": split.support_change, "support_change_pct": _pct(split.support_change),
        "rail_surface": split.rail_surface, "rail_surface_change": split.rail_surface_change,
        "rail_surface_change_pct": _pct(split.rail_surface_change),
        "rail_surface_change_low": e.recovery_low if split.rail_surface else None,
        "rail_surface_change_high": e.recovery_high if split.rail_surface else None,
        "slope_after_per_year": e.slope_after_per_year, "lasted_days_observed": e.lasted_days_observed,
        "lasted_days_projected": e.lasted_days_projected, "followed_days": e.followed_days,
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
        runs, got, vehicles = _readings(db, line, a, config)
        effect = _effect(a, runs, got, vehicles, before_days=before_days, after_days=after_days,
                         regain=regain_fraction)
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
    runs, got, vehicles = _readings(db, line, a, config)
    if not runs:
        raise ApiError(409, "action_id", _("no run of line {line} covers action {action_id}", line=repr(line.line_id),
                                                    action_id=action_id))
    effect = _effect(a, runs, got, vehicles, before_days=before_days, after_days=after_days, regain=regain_fraction)
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
