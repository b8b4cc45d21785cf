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
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import logging
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from app.analysis.condition.interventions import surface_change_days
from app.analysis.condition.lifecycle import (
    Action,
    Observation,
    PlaceEvent,
    PlaceState,
    advance_places,
    place_outlook,
)
from app.analysis.condition.run_places import find_places, segment_index
from app.analysis.condition.segment_curves import fit_segment_curves
from app.analysis.stiffness.superstructure import section_classes
from app.condition.writer import days_of, rail_surface_interventions
from app.db import places as q
from app.db import reference_crud
from app.db.models import (
    ConditionLine,
    Job,
    Place,
    PlaceAction,
    PlaceEventRow,
    PlaceObservation,
    PlaceRun,
    PlaceStatusChange,
    utcnow,
)
from app.pipeline.assemble import ENGINE_VERSION
from app.places.config import DEFAULT_PLACES_CONFIG, PlacesConfig

__all__ = ["SEGMENT_M", "SYSTEM_USER", "PlacesUpdate", "PreparedRun", "RunIndex", "method_version", "update_places",
           "apply_run", "prepare_run", "apply_prepared", "history_of", "run_index",
           "run_segment_index"]

log = logging.getLogger(__name__)

#: The store's segment length the places are found on, m.
SEGMENT_M = 10
#: Who the service's own status changes are recorded as.
SYSTEM_USER = "trackvkf"
_EPOCH = dt.datetime(1970, 1, 1, tzinfo=dt.UTC)


def method_version(job_settings: dict[str, Any] | None) -> str:
    """The version of the method a run's condition rows come from: the engine and a digest of the job's
    processing settings (the recipe), e.g. ``trackvkf-pipeline/3+1a2b3c4d5e6f``."""
    blob = json.dumps(job_settings or {}, sort_keys=True, separators=(",", ":"), default=str)
    return f"{ENGINE_VERSION}+{hashlib.sha256(blob.encode()).hexdigest()[:12]}"


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


def _classes(session: Session, line: ConditionLine, seg: np.ndarray, margin_m: float) -> np.ndarray:
    sections = reference_crud.reference_frame(session, "superstructure", line_id=line.line_id, track=line.track)
    return section_classes((seg + 0.5) * SEGMENT_M, sections["km_from"].to_numpy(dtype=float) * 1000.0,
                           sections["km_to"].to_numpy(dtype=float) * 1000.0,
                           sections["type"].to_numpy(dtype=object), boundary_margin_m=margin_m)


def line_actions(session: Session, line: ConditionLine) -> tuple[list[Action], dict[int, Any]]:
    frame = reference_crud.reference_frame(session, "maintenance", line_id=line.line_id, track=line.track)
    acts, rows = [], {}
    for r in frame.itertuples(index=False):
        day = days_of(dt.datetime.combine(r.date, dt.time(), tzinfo=dt.UTC))
        lo, hi = sorted((float(r.km_from) * 1000.0, float(r.km_to) * 1000.0))
        acts.append(Action(int(r.id), lo, hi, day, str(r.type)))
        rows[int(r.id)] = r
    return acts, rows


def _grids(values: np.ndarray, wheels: list[str], run_ids: list[int]):
    """Per run: (segments, wheel names, ln A, speed, stated 1-σ of ln A) as wheels × segments arrays."""
    order = np.argsort(values[:, 0], kind="stable")
    v_sorted = values[order]
    bounds = np.searchsorted(v_sorted[:, 0], np.asarray(run_ids, dtype=np.float64), side="left")
    ends = np.searchsorted(v_sorted[:, 0], np.asarray(run_ids, dtype=np.float64), side="right")
    out = {}
    for rid, a, b in zip(run_ids, bounds, ends, strict=True):
        part = v_sorted[a:b]
        seg = np.unique(part[:, 2].astype(np.int64))
        codes = np.unique(part[:, 1].astype(np.int64))
        la = np.full((codes.size, seg.size), np.nan)
        v = np.full_like(la, np.nan)
        sd = np.full_like(la, np.nan)
        i = np.searchsorted(codes, part[:, 1].astype(np.int64))
        j = np.searchsorted(seg, part[:, 2].astype(np.int64))
        la[i, j], v[i, j], sd[i, j] = part[:, 3], part[:, 4], part[:, 5]
        out[rid] = (seg, [wheels[c] for c in codes], la, v, sd)
    return out


def _on(src, seg: np.ndarray, wheels: list[str], values: np.ndarray) -> np.ndarray:
    """An earlier run's per-wheel values on this run's segments and wheels (NaN where it has none)."""
    s_seg, s_wheels = src[0], src[1]
    out = np.full((len(wheels), seg.size), np.nan)
    if s_seg.size == 0:
        return out
    j = np.minimum(np.searchsorted(s_seg, seg), s_seg.size - 1)
    hit = s_seg[j] == seg
    for i, w in enumerate(wheels):
        if w in s_wheels:
            out[i, hit] = values[s_wheels.index(w), j[hit]]
    return out


def _state(p: Place, obs: list[PlaceObservation], links: list[PlaceAction], version: str) -> PlaceState:
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


@dataclass(frozen=True)
class RunIndex:
    """The speed-conditioned index of a run and of its history on the run's segments and wheels.

    Attributes
    ----------
    seg : numpy.ndarray
        int64 segment numbers (``SEGMENT_M`` m each) of the run.
    wheels : list of str
        Wheel of each row.
    index : numpy.ndarray
        (wheels, segments) ``ln(A / A_ref(class, v))`` (NaN: none).
    speed : numpy.ndarray
        (wheels, segments) speed, m/s.
    history : numpy.ndarray
        (wheels, segments, runs) the index of the history runs, oldest first.
    history_days : numpy.ndarray
        Days (since 1970) of the history runs.
    classes : numpy.ndarray
        Superstructure class of each segment (None near a change of class).
    index_sd, history_sd : numpy.ndarray
        The stated 1-σ of ``index`` and ``history`` (the store's ``index_sd``; NaN: none).
    """

    seg: np.ndarray
    wheels: list[str]
    index: np.ndarray
    speed: np.ndarray
    history: np.ndarray
    history_days: np.ndarray
    classes: np.ndarray
    index_sd: np.ndarray | None = None
    history_sd: np.ndarray | None = None

    @property
    def mean_index(self) -> np.ndarray:
        """The index per segment, mean over the wheels (what a place is graded on)."""
        return _mean_over_wheels(self.index)


def _mean_over_wheels(a: np.ndarray) -> np.ndarray:
    ok = np.isfinite(a)
    n = ok.sum(axis=0)
    return np.where(n > 0, np.where(ok, a, 0.0).sum(axis=0) / np.maximum(n, 1), np.nan)


def run_index(session: Session, line: ConditionLine, run_id: int, history: list[tuple[int, dt.datetime]], *,
              config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> RunIndex | None:
    """The index of a run and of ``history`` (run id, time; oldest first) from the store's 10 m rows, with
    the line's reference curves fitted on those rows (None: the run has no 10 m rows)."""
    run_ids = [r for r, _ in history] + [run_id]
    values, wheel_names = q.segment_frame(session, run_ids, SEGMENT_M)
    grids = _grids(values, wheel_names, run_ids)
    seg, wheels, la, v, la_sd = grids[run_id]
    if seg.size == 0:
        return None
    all_seg = np.unique(values[:, 2].astype(np.int64))
    all_cls = _classes(session, line, all_seg, config.section_margin_m)
    cls_of = dict(zip(all_seg.tolist(), all_cls.tolist(), strict=True))
    row_cls = np.asarray(all_cls, dtype=object)[np.searchsorted(all_seg, values[:, 2].astype(np.int64))]
    # the curves from the run and its newest history runs (``curve_runs``: enough passes over the ±10 %
    # speed spread of a fleet; fitting a long history costs seconds a run and changes the curve little)
    fit = np.isin(values[:, 0], [r for r, _ in history[-config.curve_runs:]] + [run_id]) \
        if len(history) > config.curve_runs else np.ones(values.shape[0], dtype=bool)
    wheel_of = np.array(wheel_names, dtype=object)
    curves = fit_segment_curves(values[fit, 2].astype(np.int64), values[fit, 3], values[fit, 4], values[fit, 0],
                                wheel_of[values[fit, 1].astype(np.int64)], row_cls[fit],
                                min_locations=config.curve_min_locations)
    classes = np.array([cls_of[int(s)] for s in seg.tolist()], dtype=object)
    idx = segment_index(la, v, classes, curves)
    hist = [_on(grids[r], seg, wheels, segment_index(grids[r][2], grids[r][3],
                                                     np.array([cls_of[int(s)] for s in grids[r][0].tolist()],
                                                              dtype=object), curves))
            for r, _ in history]
    hist_sd = [_on(grids[r], seg, wheels, grids[r][4]) for r, _ in history]
    return RunIndex(seg=seg, wheels=wheels, index=idx, speed=v,
                    history=np.stack(hist, axis=2) if hist else np.zeros((*idx.shape, 0)),
                    history_days=np.array([days_of(t) for _, t in history], dtype=np.float64), classes=classes,
                    index_sd=la_sd, history_sd=np.stack(hist_sd, axis=2) if hist_sd else np.zeros((*idx.shape, 0)))


def run_segment_index(session: Session, line: ConditionLine, run_id: int, *,
                      config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> tuple[np.ndarray, np.ndarray]:
    """The speed-conditioned index per 10 m segment of a run (mean over the wheels) as the places use it:
    segment numbers (int64) and the index (NaN: none).

    A run applied to its line's places: the curves of its method version's history, exactly as the places
    were found on it. Another run: the curves of the line's most recent runs up to it (``history_runs``).
    """
    from sqlalchemy import select

    from app.db.models import ConditionRun

    when = q.run_time(session, run_id)
    if when is None:
        return np.zeros(0, np.int64), np.zeros(0)
    applied = q.applied_run(session, run_id)
    if applied is not None:
        history = q.history_runs(session, line.id, when, applied.method_version,
                                 scan_runs=max(config.place.history_runs, 60),
                                 window_days=config.place.trend_window_days)
    else:
        rows = session.execute(select(ConditionRun.run_id, ConditionRun.run_time).where(
            ConditionRun.line_key == line.id, ConditionRun.run_time < when)
            .order_by(ConditionRun.run_time.desc()).limit(config.place.history_runs)).all()
        history = sorted(((int(r), t) for r, t in rows), key=lambda x: (x[1], x[0]))
    ri = run_index(session, line, run_id, history, config=config)
    if ri is None:
        return np.zeros(0, np.int64), np.zeros(0)
    return ri.seg, ri.mean_index


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
    """

    run_id: int
    when: dt.datetime
    version: str
    history: list[tuple[int, dt.datetime]]
    index: RunIndex
    found: list


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
    params = config.place
    return q.history_runs(session, line.id, q.run_time(session, run_id), version,
                          scan_runs=max(params.history_runs, 60), window_days=params.trend_window_days)


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
    surface_days = surface_change_days(ri.seg, SEGMENT_M, *rail_surface_interventions(session, line.line_id, line.track),
                                       now_day)
    found = find_places(ri.seg, ri.index, ri.history, ri.history_days, now_day, ri.classes,
                        segment_m=SEGMENT_M, params=params, index_sd=ri.index_sd, history_sd=ri.history_sd,
                        surface_days=surface_days)
    return PreparedRun(run_id, when, version, hist_ids, ri, found)


def apply_run(session: Session, run_id: int, line: ConditionLine, version: str, *,
              config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> PlacesUpdate:
    """Apply one run to the line's places (no savepoint, no alerts: :func:`update_places` wraps it)."""
    q.lock_places(session)
    prep = prepare_run(session, run_id, line, version, config=config)
    if isinstance(prep, PlacesUpdate):
        return prep
    return apply_prepared(session, line, prep, config=config)


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
    known = [_state(p, obs[p.id], links[p.id], version) for p in rows]
    version_runs = {p.id: {o.run_id for o in obs[p.id] if o.method_version == version} for p in rows}
    before = {k.id: (k.active, k.listed, list(k.actions)) for k in known}
    covered = (float(seg.min() * SEGMENT_M), float((seg.max() + 1) * SEGMENT_M))
    events, _, _ = advance_places(known, found, run_id=run_id, day=now_day, covered_m=covered,
                                  params=config.lifecycle, next_id=q.next_place_id(session), place_params=params,
                                  actions=acts)
    kept = {k.id for k in known}
    q.delete_places(session, [i for i in by_id if i not in kept])
    speed_kmh = _mean_over_wheels(v) * 3.6
    written = _write(session, line, run_id, when, version, known, by_id, before, events, acts, act_rows,
                     seg, wheels, speed_kmh, version_runs, config)
    session.add(PlaceRun(run_id=run_id, line_key=line.id, run_time=when, method_version=version,
                         start_m=covered[0], end_m=covered[1], n_places=len(found), n_events=len(written)))
    session.flush()
    return PlacesUpdate(True, None, version, len(found), written)


def _speed(seg: np.ndarray, speed_kmh: np.ndarray, start_m: float, end_m: float) -> float | None:
    a = np.searchsorted(seg, int(np.floor(start_m / SEGMENT_M)))
    b = np.searchsorted(seg, int(np.ceil(end_m / SEGMENT_M)))
    part = speed_kmh[a:b]
    part = part[np.isfinite(part)]
    return float(part.mean()) if part.size else None


def _wheel_labels(mask: int, wheels: list[str]) -> str:
    return ",".join(w for i, w in enumerate(wheels) if mask >> i & 1)


def _write(session: Session, line: ConditionLine, run_id: int, when: dt.datetime, version: str,
           known: list[PlaceState], by_id: dict[int, Place], before: dict, events: list[PlaceEvent],
           acts: list[Action], act_rows: dict[int, Any], seg: np.ndarray, wheels: list[str],
           speed_kmh: np.ndarray, version_runs: dict[int, set[int]], config: PlacesConfig) -> list[PlaceEventRow]:
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
        look = place_outlook(same if same.observations else st, config.levels)
        last = st.observations[-1]
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
                _set_status(session, row, "fixed", f"repaired by {what}: run {run_id} no longer finds it", when)
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
    """The service's own status change (recorded like an engineer's, by :data:`SYSTEM_USER`)."""
    if row.status == status:
        return
    session.add(PlaceStatusChange(place_id=row.id, by=SYSTEM_USER, at=utcnow(), old=row.status, new=status,
                                  comment=comment))
    row.status, row.status_comment, row.status_by, row.status_at = status, comment, SYSTEM_USER, utcnow()
