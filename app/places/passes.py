"""A place's passes: the index at the segment it is read at in its newest run and in the earlier runs, each
marked whether it is one of that run's **matched passes** (``GET /condition/places/{id}/passes``).

The segment (``at``): its peak (``"peak"``), or for a place found by its trend that does not grow at its peak
the segment where it grows fastest (``"trend"``, :func:`app.places.update.developing_segment`). The matched passes are the history a place's
change and trend are read against (:class:`~app.analysis.condition.lifecycle.PassHistory`: the earlier runs
that passed the segment at a matched speed with the same vehicle, the step test's rule; since the latest
action on the support over the segment, where the history starts anew:
:func:`~app.analysis.condition.interventions.since_actions`). On rough rails a 10 m segment's index is the
rails' response as much as the support's, and that response changes with the speed and the vehicle, so a
place's own observations (the few runs since it was found) do not show what it was read against; this answer
does. A place found by its trend states the line fitted through its matched passes and the run
(:func:`~app.analysis.condition.lifecycle.segment_trend`, as the places' update fitted it, on the rows as
stored now): what its rate and its time to limit rest on.

Every value is the speed-conditioned index ``ln(A / A_ref(class, v))`` of the segment, mean over the wheels,
as the places read it (:func:`app.places.index.run_index`, the run's method version's history): ``index`` as
the pass read it, ``matched_index`` as the place was read against it (None: not a matched pass; where the
run's vehicle has too few passes of its own, another vehicle's matched-speed passes count brought to it by
the offset between the two, :func:`~app.analysis.condition.change.vehicle_matched`).
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
from sqlalchemy.orm import Session

from app.analysis.condition.outlook import Trend
from app.analysis.condition.places import EVIDENCE_TREND
from app.analysis.condition.run_places import mean_over_wheels
from app.analysis.units import DAYS_PER_YEAR, KMH_PER_MPS
from app.condition.actions import days_of
from app.core.errors import not_found
from app.core.jsonable import finite_or_none, iso_time
from app.db import places as q
from app.db.models import ConditionLine, Place
from app.db.session import Database
from app.places.config import DEFAULT_PLACES_CONFIG, PlacesConfig
from app.places.index import SEGMENT_M, history_runs_of, run_index
from app.places.store import place_state
from app.places.update import developing_segment, support_days_of

__all__ = ["place_passes"]


def _trend_line(trend: Trend, direction: int, days: tuple[float, float], times: tuple[dt.datetime, dt.datetime],
                now_day: float) -> dict | None:
    """The fitted line from the first matched pass to the run (``days``, ``times``), in index units, with its
    rate (index units a year) and the rate's 95 % interval; None without a rate."""
    if not math.isfinite(trend.rate_per_year):
        return None
    # segment_trend fits the severity, direction · index: back to the index
    lo, hi = sorted((direction * trend.low_per_year, direction * trend.high_per_year))

    def at(day: float) -> float:
        return direction * (trend.level + trend.rate_per_year * (day - now_day) / DAYS_PER_YEAR)

    return {"rate_per_year": direction * trend.rate_per_year, "rate_low": finite_or_none(lo),
            "rate_high": finite_or_none(hi), "significant": bool(trend.significant), "n": int(trend.n),
            "from_time": iso_time(times[0]), "to_time": iso_time(times[1]),
            "from_index": at(days[0]), "to_index": at(days[1])}


def _answer(session: Session, p: Place, config: PlacesConfig) -> dict:
    line = session.get(ConditionLine, p.line_key)
    state = place_state(p, q.observations_of(session, [p.id])[p.id], [], p.method_version)
    last = state.observations[-1] if state.observations else None
    peak = int((last.peak_m if last is not None else p.peak_m) // SEGMENT_M)
    out: dict = {"place_id": p.id, "run_id": p.last_run_id, "segment_m": SEGMENT_M, "at": "peak",
                 "km_from": peak * SEGMENT_M / 1000.0, "km_to": (peak + 1) * SEGMENT_M / 1000.0,
                 "vehicle": None, "speed_kmh": None, "passes": [], "trend": None}
    when = q.run_time(session, p.last_run_id)
    if when is None or last is None:  # the run was deleted since
        return out
    history = history_runs_of(session, line, p.last_run_id, config)
    ri = run_index(session, line, p.last_run_id, history, config=config)
    if ri is None:
        return out
    now_day = days_of(when)
    passes = ri.passes(config.place.change_params(), support_days=support_days_of(session, line, ri.seg, now_day))
    # a place found by its trend: the segment its trend is read at (update.developing_segment), else its peak
    got = developing_segment(state, ri, passes, now_day) if last.evidence & EVIDENCE_TREND else None
    if got is not None:
        k, trend = got
        out["at"] = "peak" if int(ri.seg[k]) == peak else "trend"
    else:
        k, trend = int(np.searchsorted(ri.seg, peak)), None
        if k >= ri.seg.size or int(ri.seg[k]) != peak:
            return out
    seg = int(ri.seg[k])
    out["km_from"], out["km_to"] = seg * SEGMENT_M / 1000.0, (seg + 1) * SEGMENT_M / 1000.0
    days, matched = passes.series(k, float(ri.mean_index[k]), now_day)
    # every history run's index and speed at the segment, matched or not, and the run's own
    index = np.append(mean_over_wheels(ri.history[:, k:k + 1, :])[0], ri.mean_index[k]) if history \
        else ri.mean_index[k:k + 1]
    speed = mean_over_wheels(ri.speed[:, k:k + 1])
    if history and ri.history_speed is not None:
        speed = np.append(mean_over_wheels(ri.history_speed[:, k:k + 1, :])[0], speed)
    vehicles = [*(ri.history_vehicle.tolist() if ri.history_vehicle is not None else [None] * len(history)),
                ri.vehicle]
    runs = [*history, (p.last_run_id, when)]
    out["vehicle"] = ri.vehicle
    out["speed_kmh"] = finite_or_none(float(speed[-1]) * KMH_PER_MPS)
    out["passes"] = [
        {"run_id": int(r), "run_time": iso_time(t), "index": float(index[j]),
         "matched_index": finite_or_none(float(matched[j])),
         "speed_kmh": finite_or_none(float(speed[j]) * KMH_PER_MPS), "vehicle": vehicles[j],
         "this_run": j == len(runs) - 1}
        for j, (r, t) in enumerate(runs) if math.isfinite(float(index[j]))]
    if trend is not None:
        j0 = int(np.flatnonzero(np.isfinite(matched))[0])
        out["trend"] = _trend_line(trend, state.direction, (float(days[j0]), now_day), (runs[j0][1], when), now_day)
    return out


def place_passes(db: Database, place_id: int, config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> dict:
    """The segment a place is read at in its newest run and in the earlier runs, each marked whether it is a
    matched pass, and for a place found by its trend the line fitted through them (module docstring; 404 naming
    ``place_id``)."""
    with db.read() as session:
        p = session.get(Place, place_id)
        if p is None:
            raise not_found("place", place_id)
        return _answer(session, p, config)
