"""The places' rows written back after a run advanced them, and read into the lifecycle's state.

:func:`place_state` turns a place's rows (the place, its observations, its action links) into the
lifecycle's :class:`~app.analysis.condition.lifecycle.PlaceState`; :func:`write_run` writes what
:func:`~app.analysis.condition.lifecycle.advance_places` did with a run back: each place's state, the
run's observations, the events, the action links, and the service's own status changes (a place an
action repaired is set ``fixed``; one marked ``fixed`` that the run finds again is reopened), recorded
by :data:`SYSTEM_USER`. Called by :func:`app.places.update.apply_prepared` in its transaction.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import replace
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from app.analysis.condition.lifecycle import (
    Action,
    Observation,
    PlaceEvent,
    PlaceState,
    place_outlook,
)
from app.analysis.condition.outlook import Trend
from app.analysis.condition.places import EVIDENCE_TREND
from app.db.models import (
    ConditionLine,
    Place,
    PlaceAction,
    PlaceEventRow,
    PlaceObservation,
    PlaceStatusChange,
    utcnow,
)
from app.places.config import PlacesConfig
from app.places.index import SEGMENT_M

__all__ = ["SYSTEM_USER", "place_state", "write_run"]

#: Who the service's own status changes are recorded as.
SYSTEM_USER = "trackvkf"


def place_state(p: Place, obs: list[PlaceObservation], links: list[PlaceAction], version: str) -> PlaceState:
    """A place's rows as the lifecycle's state (its baseline only when measured with ``version``)."""
    same = p.method_version == version
    return PlaceState(
        id=p.id, direction=int(p.direction), start_m=p.start_m, end_m=p.end_m, peak_m=p.peak_m, cls=p.cls,
        baseline=p.baseline if same else None, explained_by=p.explained_by,
        actions=[a.action_id for a in links if a.relation in ("linked", "repaired")], tier=int(p.tier),
        listed=bool(p.listed), active=bool(p.active), misses=int(p.misses), lower_runs=int(p.lower_runs),
        observations=[Observation(run_id=o.run_id, day=o.day, start_m=o.start_m, end_m=o.end_m, centre_m=o.centre_m,
                                  peak_m=o.peak_m, level=o.level, change=np.nan if o.change is None else o.change,
                                  tier=int(o.tier), severity=o.severity, evidence=int(o.evidence),
                                  wheels=int(o.wheels), level_sd=_nan(o.level_sd), change_sd=_nan(o.change_sd),
                                  severity_sd=_nan(o.severity_sd)) for o in obs],
    )


def _nan(x: float | None) -> float:
    return float("nan") if x is None else float(x)


def _finite(x: float) -> float | None:
    return float(x) if x is not None and np.isfinite(x) else None


def _speed(seg: np.ndarray, speed_kmh: np.ndarray, start_m: float, end_m: float) -> float | None:
    a = np.searchsorted(seg, int(np.floor(start_m / SEGMENT_M)))
    b = np.searchsorted(seg, int(np.ceil(end_m / SEGMENT_M)))
    part = speed_kmh[a:b]
    part = part[np.isfinite(part)]
    return float(part.mean()) if part.size else None


def _wheel_labels(mask: int, wheels: list[str]) -> str:
    return ",".join(w for i, w in enumerate(wheels) if mask >> i & 1)


def write_run(session: Session, line: ConditionLine, run_id: int, when: dt.datetime, version: str,
           known: list[PlaceState], by_id: dict[int, Place], before: dict, events: list[PlaceEvent],
           acts: list[Action], act_rows: dict[int, Any], seg: np.ndarray, wheels: list[str],
           speed_kmh: np.ndarray, version_runs: dict[int, set[int]], config: PlacesConfig,
           trends: dict[int, Trend] | None = None) -> list[PlaceEventRow]:
    """Write the places a run advanced (``known``: the lifecycle's state after it; ``by_id``: their rows
    before; ``before``: (active, listed, actions) before) and its ``events``; the event rows written.
    ``trends``: the severity trend of the developing places (by id) over their segment's history."""
    now = utcnow()
    out: list[PlaceEventRow] = []

    def event(place_id: int, kind: str, old: int | None = None, new: int | None = None,
              action_id: int | None = None, alerted: bool = False) -> None:
        row = PlaceEventRow(place_id=place_id, run_id=run_id, kind=kind, old_tier=old, new_tier=new,
                            action_id=action_id, alerted=alerted, time=when, created_at=now)
        session.add(row)
        out.append(row)

    act_by_id = {a.id: a for a in acts}
    lifecycle_events: dict[int, list[PlaceEvent]] = {}
    for e in events:
        lifecycle_events.setdefault(e.place_id, []).append(e)
    for st in known:
        new_obs = [o for o in st.observations if o.run_id == run_id]
        row = by_id.get(st.id)
        fresh = row is None
        if fresh:
            first = st.observations[0]
            row = Place(id=st.id, line_key=line.id, first_run_id=first.run_id, first_seen=when, status="open",
                        created_at=now, method_version=version)
            session.add(row)
        if new_obs:
            row.method_version = version
        # the outlook over the observations of the place's current method version
        mine = version_runs.get(st.id, set()) | {run_id}
        same = replace(st, observations=[o for o in st.observations if o.run_id in mine])
        look = place_outlook(same if same.observations else st, config.levels, trend=(trends or {}).get(st.id),
                             changes=config.place.changes)
        last = st.observations[-1]
        # a developing place's outlook is its segment's trend, fitted by the run that last found it by its trend
        # (update.developing_trends); a later run that does not read the place keeps it (its few observations
        # alone have too few runs for a rate: the real line's developing place lost its date that way)
        keep_outlook = (not fresh and not new_obs and st.id not in (trends or {}) and bool(last.evidence & EVIDENCE_TREND)
                        and row.rate_per_year is not None and row.tier == st.tier)
        # the peak and level of the latest observation (a held place keeps its extent, its peak moves)
        row.direction, row.start_m, row.end_m, row.peak_m = st.direction, st.start_m, st.end_m, last.peak_m
        row.centre_m, row.cls, row.baseline, row.explained_by = last.centre_m, st.cls, _finite(st.baseline), \
            st.explained_by
        row.tier, row.listed, row.active, row.misses, row.lower_runs = st.tier, st.listed, st.active, st.misses, \
            st.lower_runs
        row.level, row.change, row.severity = last.level, _finite(last.change), last.severity
        row.level_sd, row.change_sd, row.severity_sd = (_finite(last.level_sd), _finite(last.change_sd),
                                                        _finite(last.severity_sd))
        row.evidence, row.wheels = last.evidence, last.wheels
        if new_obs:
            row.wheel_labels = _wheel_labels(last.wheels, wheels)
        row.runs_confirming = st.confirmations
        if not keep_outlook:
            row.tendency = look.tendency
            row.rate_per_year = _finite(look.trend.rate_per_year) if look.trend.significant or look.trend.n >= 3 \
                else None
            row.rate_low = _finite(look.trend.low_per_year) if row.rate_per_year is not None else None
            row.rate_high = _finite(look.trend.high_per_year) if row.rate_per_year is not None else None
            row.next_limit = _finite(look.next_limit)
            row.days_to_next = _finite(look.projection.days)
        row.last_run_id, row.last_confirmed = last.run_id, (when if last.run_id == run_id else row.last_confirmed)
        row.updated_at = now
        for o in new_obs:
            session.add(PlaceObservation(place_id=st.id, run_id=run_id, run_time=when, day=o.day, start_m=o.start_m,
                                         end_m=o.end_m, centre_m=o.centre_m, peak_m=o.peak_m, level=o.level,
                                         change=_finite(o.change), tier=o.tier, severity=o.severity,
                                         level_sd=_finite(o.level_sd), change_sd=_finite(o.change_sd),
                                         severity_sd=_finite(o.severity_sd),
                                         evidence=o.evidence, wheels=o.wheels,
                                         wheel_labels=row.wheel_labels if o.wheels else "",
                                         speed_kmh=_speed(seg, speed_kmh, o.start_m, o.end_m),
                                         method_version=version))
        was_active, was_listed, was_actions = before.get(st.id, (True, False, []))
        # action links
        relation = {}
        if st.explained_by is not None and (fresh or st.explained_by not in was_actions):
            relation[st.explained_by] = "explained"
        for aid in st.actions:
            if aid not in was_actions:
                relation[aid] = "linked"
        for e in lifecycle_events.get(st.id, []):
            if e.kind == "repaired" and e.action_id is not None:
                relation[e.action_id] = "repaired"
        for aid, rel in relation.items():
            a, r = act_by_id.get(aid), act_rows.get(aid)
            if a is None:
                continue
            link = session.get(PlaceAction, (st.id, aid))
            if link is None:
                link = PlaceAction(place_id=st.id, action_id=aid, relation=rel, kind=a.kind, date=r.date,
                                   km_from=a.start_m / 1000.0, km_to=a.end_m / 1000.0)
                session.add(link)
                if rel == "linked":
                    event(st.id, "linked", action_id=aid)
            else:
                link.relation = rel
        for e in lifecycle_events.get(st.id, []):
            if e.kind == "new":
                event(st.id, "new", None, e.new_tier, alerted=True)
            elif e.kind == "tier":
                event(st.id, "tier_up" if e.new_tier > e.old_tier else "tier_down", e.old_tier, e.new_tier,
                      alerted=True)
            elif e.kind == "back":
                event(st.id, "back", e.old_tier, e.new_tier, alerted=True)
                if row.status == "fixed":
                    _set_status(session, row, "open", f"marked fixed, found again by run {run_id}", when)
            elif e.kind == "repaired":
                event(st.id, "repaired", e.old_tier, e.new_tier, action_id=e.action_id)
                r = act_rows.get(e.action_id)
                what = f"{r.type} of {r.date.isoformat()} (action {e.action_id})" if r is not None \
                    else f"action {e.action_id}"
                # a repaired place is fixed as of the repair's day, not the day its run was processed
                repaired = dt.datetime.combine(r.date, dt.time(12, 0), tzinfo=dt.UTC) if r is not None else when
                _set_status(session, row, "fixed", f"repaired by {what}: run {run_id} no longer finds it", repaired)
        kinds = {e.kind for e in lifecycle_events.get(st.id, [])}
        if was_active and not st.active and "repaired" not in kinds and was_listed:
            event(st.id, "inactive", st.tier, st.tier)
        # a place marked fixed that a run finds again after it was marked reopens with its history
        # (found by the run's tests, not merely held near its level; the run is applied after the mark)
        if new_obs and row.status == "fixed" and "back" not in kinds and "repaired" not in kinds \
                and st.listed and st.active and any(o.evidence and o.wheels for o in new_obs):
            event(st.id, "back", st.tier, st.tier, alerted=True)
            _set_status(session, row, "open", f"marked fixed, found again by run {run_id}", when)
    session.flush()
    return out


def _set_status(session: Session, row: Place, status: str, comment: str, when: dt.datetime) -> None:
    """The service's own status change (recorded like an engineer's, by :data:`SYSTEM_USER`).

    The status holds as of ``when`` (the repair's day for a place a repair fixed, the run's time for
    one a run found again); the history records when the service wrote it.
    """
    if row.status == status:
        return
    session.add(PlaceStatusChange(place_id=row.id, by=SYSTEM_USER, at=utcnow(), old=row.status, new=status,
                                  comment=comment))
    row.status, row.status_comment, row.status_by, row.status_at = status, comment, SYSTEM_USER, when
