"""After a run's condition rows are published: its places, and the line's places advanced by it.

Called by the places follow-up of the publish step (:mod:`app.places.followup`, after the commit that
publishes the run, both worker modes): :func:`prepare_run` (the run's places found: reads only, no write
lock) and then, in a short write transaction, :func:`update_places` with them (inside a savepoint). The
one-transaction path (:func:`apply_run`: both parts) serves ``trackvkf apply-places`` and the tests.

For a run with condition rows, in time order:

1. the run's **method version** (:func:`method_version`: the engine and the job's processing
   settings) — places are compared **only within one method version**: the history a run's step
   and trend tests see, and the reference curves of its index, are the store's rows of earlier runs
   processed the same way; a known place measured with another version loses its baseline (its change
   is measured afresh) and its trend is fitted over the observations of the run's version only. A run
   reprocessed with a new recipe therefore reads as the track it measures, never as a change of it;
2. the speed-conditioned index ``ln(A / A_ref(class, v))`` of the run and of that history from the
   store's 10 m rows (curves fitted on them, :func:`~app.analysis.condition.segment_curves.fit_segment_curves`),
   the run's places (:func:`~app.analysis.condition.run_places.find_places`);
3. the line's known places advanced
   (:func:`~app.analysis.condition.lifecycle.advance_places`, with the line's imported maintenance
   actions) and written back: state, the run's observations, events, action links;
4. workflow: a place an action repaired is set ``fixed`` (by ``trackvkf``, the action in the comment);
   a place marked ``fixed`` that a later run finds again is reopened (event ``back``, status
   ``open``) with its history;
5. the alerts of its new places, tier changes and places back (:mod:`app.places.alerts`).

A run older than the newest run already applied to its line, or applied already (reprocessed), does
not advance the places (the lifecycle is a sequence in time): its summary says so.

The index of step 2 is :mod:`app.places.index`; the rows written back in steps 3 and 4 are
:mod:`app.places.store`'s.
"""

from __future__ import annotations

import datetime as dt
import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from app.analysis.condition.change import axle_labels
from app.analysis.condition.interventions import latest_action_days
from app.analysis.condition.lifecycle import (
    Action,
    PassHistory,
    PlaceState,
    advance_places,
    segment_trend,
)
from app.analysis.condition.outlook import Trend
from app.analysis.condition.places import EVIDENCE_TREND
from app.analysis.condition.run_places import find_places, mean_over_wheels
from app.analysis.units import KMH_PER_MPS
from app.condition.actions import days_of, rail_surface_interventions, support_interventions
from app.db import places as q
from app.db import reference_crud
from app.db.models import ConditionLine, Job, PlaceEventRow, PlaceRun
from app.places.config import DEFAULT_PLACES_CONFIG, PlacesConfig
from app.places.index import SEGMENT_M, RunIndex, method_version, run_index, version_history
from app.places.store import place_state, write_run

__all__ = ["PlacesUpdate", "PreparedRun", "update_places", "apply_run", "prepare_run", "apply_prepared",
           "history_of", "line_actions"]

log = logging.getLogger(__name__)


@dataclass
class PlacesUpdate:
    """What a run did to its line's places (``applied`` False: nothing, and why)."""

    applied: bool
    reason: str | None = None
    method_version: str | None = None
    n_found: int = 0
    events: list[PlaceEventRow] = field(default_factory=list)
    deliveries: list[int] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        """For the job's metadata (``meta["condition"]["places"]``)."""
        if not self.applied:
            return {"applied": False, "reason": self.reason}
        return {"applied": True, "method_version": self.method_version, "found": self.n_found,
                "events": [{"place_id": e.place_id, "kind": e.kind} for e in self.events],
                "webhook_deliveries": len(self.deliveries)}


def update_places(session: Session, run_id: int, line: ConditionLine, job_id: int, *,
                  config: PlacesConfig = DEFAULT_PLACES_CONFIG, alerts: bool = True,
                  prepared: PreparedRun | None = None, raise_errors: bool = False) -> PlacesUpdate:
    """Apply a published run to its line's places, in a savepoint of the caller's transaction (module
    docstring). Never raises for a problem of the places (unless ``raise_errors``): it is logged and
    reported in the summary.

    ``prepared``: the run's places found already (:func:`prepare_run`, in an earlier read transaction:
    the places follow-up, :mod:`app.places.followup`); this transaction then only advances the line's
    places with them (:func:`apply_prepared`).
    """
    try:
        with session.begin_nested():
            if prepared is None:
                job = session.get(Job, job_id)
                version = method_version(job.settings if job is not None else None)
                out = apply_run(session, run_id, line, version, config=config)
            else:
                q.lock_places(session)
                out = _not_applicable(session, run_id, line, prepared.version) or \
                    apply_prepared(session, line, prepared, config=config)
            if alerts and config.alerts and out.applied:
                from app.places.alerts import enqueue_place_events

                out.deliveries = enqueue_place_events(session, run_id, line, out.events)
            return out
    except Exception as exc:  # noqa: BLE001 - the run's publication must not fail for its places
        if raise_errors:
            raise
        log.exception("places of run %s not updated", run_id)
        return PlacesUpdate(applied=False, reason=f"error: {type(exc).__name__}: {exc}")


def line_actions(session: Session, line: ConditionLine) -> tuple[list[Action], dict[int, Any]]:
    """The line's imported maintenance actions as the lifecycle sees them, and their rows by id."""
    frame = reference_crud.reference_frame(session, "maintenance", line_id=line.line_id, track=line.track)
    acts, rows = [], {}
    for r in frame.itertuples(index=False):
        day = days_of(dt.datetime.combine(r.date, dt.time(), tzinfo=dt.UTC))
        lo, hi = sorted((float(r.km_from) * 1000.0, float(r.km_to) * 1000.0))
        acts.append(Action(int(r.id), lo, hi, day, str(r.type)))
        rows[int(r.id)] = r
    return acts, rows


@dataclass(frozen=True)
class PreparedRun:
    """A run's places found from the store (the long part of applying it: the store's rows read, the curves
    fitted, :func:`~app.analysis.condition.run_places.find_places`): :func:`prepare_run` makes it,
    :func:`apply_prepared` advances the line's places with it.

    Attributes
    ----------
    run_id : int
    when : datetime.datetime
        The run's time.
    version : str
        Its method version (:func:`method_version`).
    history : list of (int, datetime.datetime)
        The history runs its tests saw (run id, time; oldest first).
    index : RunIndex
        The run's index and its history's.
    found : list
        The run's places (:func:`~app.analysis.condition.run_places.find_places`).
    support_days : numpy.ndarray or None
        Per segment of ``index`` the day of the latest action on the support over it (NaN: none; None: no
        such action on the line): the history its tests and its places' passes start from.
    """

    run_id: int
    when: dt.datetime
    version: str
    history: list[tuple[int, dt.datetime]]
    index: RunIndex
    found: list
    support_days: np.ndarray | None = None


def _not_applicable(session: Session, run_id: int, line: ConditionLine, version: str) -> PlacesUpdate | None:
    """Why the run cannot be applied to its line's places now (None: it can)."""
    when = q.run_time(session, run_id)
    if when is None:
        return PlacesUpdate(False, "the run has no condition rows", version)
    if q.applied_run(session, run_id) is not None:
        return PlacesUpdate(False, "the run was applied to its line's places already (reprocessed: its places "
                                   "stay as first found)", version)
    latest = q.latest_applied_time(session, line.id)
    if latest is not None and when < latest:
        return PlacesUpdate(False, "the run is older than the newest run applied to its line's places", version)
    return None


def history_of(session: Session, run_id: int, line: ConditionLine, version: str, *,
               config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> list[tuple[int, dt.datetime]]:
    """The history runs a run's tests see (run id, time; oldest first): earlier applied runs of its version."""
    return version_history(session, line, q.run_time(session, run_id), version, config)


def prepare_run(session: Session, run_id: int, line: ConditionLine, version: str, *,
                config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> PreparedRun | PlacesUpdate:
    """Find a run's places from the store (reads only): a :class:`PreparedRun`, or why the run is not applied."""
    if (why := _not_applicable(session, run_id, line, version)) is not None:
        return why
    when = q.run_time(session, run_id)
    params = config.place
    hist_ids = history_of(session, run_id, line, version, config=config)
    ri = run_index(session, line, run_id, hist_ids, config=config)
    if ri is None:
        return PlacesUpdate(False, "the run has no 10 m condition rows", version)
    now_day = days_of(when)
    surface_days = latest_action_days(ri.seg, SEGMENT_M, *rail_surface_interventions(session, line.line_id, line.track),
                                      now_day)
    support = support_days_of(session, line, ri.seg, now_day)
    found = find_places(ri.seg, ri.index, ri.history, ri.history_days, now_day, ri.classes,
                        segment_m=SEGMENT_M, params=params, index_sd=ri.index_sd, history_sd=ri.history_sd,
                        surface_days=surface_days, speed=ri.speed, history_speed=ri.history_speed,
                        vehicle=ri.vehicle, history_vehicle=ri.history_vehicle, support_days=support,
                        axles=axle_labels(ri.wheels))
    return PreparedRun(run_id, when, version, hist_ids, ri, found, support)


def support_days_of(session: Session, line: ConditionLine, seg: np.ndarray, now_day: float) -> np.ndarray | None:
    """Per segment (``SEGMENT_M`` m each) the day of the latest action on the support over it up to
    ``now_day`` (NaN: none; None: the line has no such action): where a segment's history starts anew
    (:func:`~app.analysis.condition.interventions.since_actions`)."""
    acts = support_interventions(session, line.line_id, line.track)
    return latest_action_days(seg, SEGMENT_M, *acts, now_day) if acts[0].size else None


def apply_run(session: Session, run_id: int, line: ConditionLine, version: str, *,
              config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> PlacesUpdate:
    """Apply one run to the line's places (no savepoint, no alerts: :func:`update_places` wraps it)."""
    q.lock_places(session)
    prep = prepare_run(session, run_id, line, version, config=config)
    if isinstance(prep, PlacesUpdate):
        return prep
    return apply_prepared(session, line, prep, config=config)


def developing_segment(st: PlaceState, ri: RunIndex, passes: PassHistory, now_day: float) -> tuple[int, Trend] | None:
    """The segment a developing place's trend is read at, and that trend: its peak segment where the matched
    passes and the run grow its way there with a significant rate
    (:func:`~app.analysis.condition.lifecycle.segment_trend`); else, of its segments in the run (its newest
    observation's extent), the one growing fastest its way with a significant rate; else its peak. None where
    the run has no index at its peak and none of its segments grows significantly.

    A place is graded at its peak, its most severe segment; where it grows may be beside it. Measured on the
    test demo's history: the place developing softer at −1 ln unit a year lies inside a lasting soft spot whose
    peak does not move, and read "stable" at the peak (+0.06 a year, not significant) while its segments
    30–60 m beside it fell −0.5 … −1.1 a year, each significant. The peak first: the fastest of several noisy
    rates is biased high (the demo's place growing harder, truth +1.2 a year, read +1.23 at its peak, +1.35 at
    its fastest segment).
    """
    last = st.observations[-1]

    def at(k: int) -> Trend:
        days, values = passes.series(k, float(ri.mean_index[k]), now_day)
        return segment_trend(st, days, values, now_day=now_day)

    peak = int(last.peak_m // SEGMENT_M)
    kp = int(np.searchsorted(ri.seg, peak))
    on_peak = kp < ri.seg.size and ri.seg[kp] == peak
    peak_trend = at(kp) if on_peak else None
    if peak_trend is not None and peak_trend.significant and peak_trend.rate_per_year > 0:
        return kp, peak_trend
    inside = np.flatnonzero((ri.seg >= int(last.start_m // SEGMENT_M)) & (ri.seg * SEGMENT_M < last.end_m))
    best: tuple[int, Trend] | None = None
    for k in inside.tolist():
        if on_peak and k == kp:  # its trend is read above: no significant growth
            continue
        tr = at(k)
        if tr.significant and tr.rate_per_year > 0 and (best is None or tr.rate_per_year > best[1].rate_per_year):
            best = (k, tr)
    if best is not None:
        return best
    return (kp, peak_trend) if peak_trend is not None else None


def developing_trends(known: list[PlaceState], run_id: int, ri: RunIndex, now_day: float,
                      passes: PassHistory) -> dict[int, Trend]:
    """The severity trends of the places the run found by their trend (evidence ``trend``), each at the segment it
    is read at (:func:`developing_segment`: its peak where it grows there, else where it grows fastest), over
    that segment's matched passes and the run, by place id."""
    out: dict[int, Trend] = {}
    for st in known:
        last = st.observations[-1] if st.observations else None
        if last is None or last.run_id != run_id or not (last.evidence & EVIDENCE_TREND):
            continue
        got = developing_segment(st, ri, passes, now_day)
        if got is not None:
            out[st.id] = got[1]
    return out


def apply_prepared(session: Session, line: ConditionLine, prep: PreparedRun, *,
                   config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> PlacesUpdate:
    """Advance the line's places with a run's places found (:func:`prepare_run`) and write them back
    (the caller has checked that the run can be applied: :func:`apply_run`, the follow-up)."""
    run_id, when, version, ri, found = prep.run_id, prep.when, prep.version, prep.index, prep.found
    seg, wheels, v = ri.seg, ri.wheels, ri.speed
    now_day = days_of(when)
    params = config.place
    acts, act_rows = line_actions(session, line)
    rows = q.line_places(session, line.id)
    by_id = {p.id: p for p in rows}
    obs = q.observations_of(session, list(by_id))
    links = q.actions_of(session, list(by_id))
    known = [place_state(p, obs[p.id], links[p.id], version) for p in rows]
    version_runs = {p.id: {o.run_id for o in obs[p.id] if o.method_version == version} for p in rows}
    before = {k.id: (k.active, k.listed, list(k.actions)) for k in known}
    covered = (float(seg.min() * SEGMENT_M), float((seg.max() + 1) * SEGMENT_M))
    passes = ri.passes(params.change_params(), support_days=prep.support_days)
    events, _, _ = advance_places(known, found, run_id=run_id, day=now_day, covered_m=covered,
                                  params=config.lifecycle, next_id=q.next_place_id(session), place_params=params,
                                  actions=acts, passes=passes)
    kept = {k.id for k in known}
    q.delete_places(session, [i for i in by_id if i not in kept])
    speed_kmh = mean_over_wheels(v) * KMH_PER_MPS
    written = write_run(session, line, run_id, when, version, known, by_id, before, events, acts, act_rows,
                     seg, wheels, speed_kmh, version_runs, config, trends=developing_trends(known, run_id, ri, now_day, passes))
    session.add(PlaceRun(run_id=run_id, line_key=line.id, run_time=when, method_version=version,
                         start_m=covered[0], end_m=covered[1], n_places=len(found), n_events=len(written)))
    session.flush()
    return PlacesUpdate(True, None, version, len(found), written)
