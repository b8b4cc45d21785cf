"""The lifecycle of places over runs: identity, confirmation, tier changes and the alerts they raise.

A run's places (:func:`~app.analysis.condition.run_places.find_places`) are
matched to the known places of the line (:func:`~app.analysis.condition.identity.match_places`,
every known place whatever its workflow status, so a place that comes back
after it was marked fixed keeps its id and history). Then:

* a known place found again is **confirmed** by the run: its extent becomes
  today's, its observation (day, level, change, tier) is added;
* a place keeps the index it had **before it appeared** (its *baseline*: the
  level minus the change of the run that first found it by a step). Its
  change is measured against that baseline from then on, not against a
  rolling history that slowly absorbs a lasting change — given the run's
  matched passes (:class:`PassHistory`), against its baseline **at the run's
  pass** (same vehicle, matched speed: the median of those passes before the
  place was first seen, else its first such pass since; none: the run's own
  step grades it and does not hold it). It is read where it
  departs most from that baseline on its own ground (the run's extent within
  its known one), not at the run's peak (where the run's step test fired
  against each segment's rolling history: at a developing place that is the
  edge the growth has just reached, while its middle, absorbed by its own
  history, is found by the trend alone); a known place the
  run's tests did not flag is still **held** (confirmed) while its extent
  stays ``hold_change`` away from its baseline in its direction beyond the
  reading's stated 1-σ (the departure less the level's 1-σ); a change against
  the baseline carries the reading's level 1-σ and is graded on its lower
  bound; a baseline is taken later only from a step on the place's own extent;
  where the baseline was an anomaly of the other side and the reading is none
  of the place's side, the change is that anomaly **receding**: graded as the
  run graded it, and it holds nothing (:func:`_receding`);
* active places of one direction within ``gap_m`` of each other are **one
  place** (:func:`_merge_pieces`): merged over the union of their extents, the
  others kept as its inactive pieces, never matched or held on their own;
* a place neither found nor held by a run that covered its extent with an
  index (a run without one there — no reference curve at the speed it passed
  the place — could not see it) is **missed** by it (``misses`` counts the consecutive ones), and after
  ``drop_after`` misses it is no longer **active** (not on the list until
  found again; a place never listed is then forgotten) — a repaired place
  goes back to its baseline and drops out this way;
* a place is **listed** (on the work list, and alerted) once ``min_confirmations``
  runs found it — a single run's exceedance that the next run does not repeat
  is noise of that run — or at once when its tier reaches ``confirm_tier``
  (what needs action now is not held back by a run);
* its **tier** rises at once; it falls only when ``tier_down_runs`` consecutive
  confirming runs put it lower (no alert ping-pong for a place at a limit).

**Maintenance** (:class:`Action`: the imported actions of the line):

* a place that appears within ``explain_days`` after an action covering at
  least half of it is that action's **effect** (``explained_by``): a tamping
  lowers the amplitude over its extent, a grinding changes the rail's share of
  it — neither is a new defect of the track's support. It is kept, with its
  observations, but never listed or alerted;
* an action dated after a known place was first seen and covering at least
  half of it is **linked** to it; when the first run after the action finds
  the place neither flagged nor held, the action **repaired** it (event
  ``repaired`` with the action, the place is no longer active at once). A
  place the action did not repair stays, linked.

Events (:class:`PlaceEvent`) — ``new`` when a place becomes listed, ``tier``
when a listed place's tier changes, ``back`` when an inactive place is found
again, ``repaired`` when an action repaired it — are what alerts are sent for;
nothing else in a run raises one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from app.analysis.condition.change import ChangeParams, matched_passes
from app.analysis.condition.identity import covering_actions, match_places, tendency
from app.analysis.condition.interventions import since_actions
from app.analysis.condition.outlook import Projection, Trend, linear_trend, time_to_limit
from app.analysis.condition.places import EVIDENCE_STEP, EVIDENCE_TREND
from app.analysis.condition.run_places import (
    PlaceParams,
    RunPlaces,
    graded_level,
    mean_over_wheels,
)
from app.analysis.condition.tiers import TIER_ALERT, TIER_INTERVENTION, TierLimits, TierTable

#: The evidence whose change against the history grades a found place's tier (find_places: a step's, and a
#: trend's change so far against its matched passes); a place found by its level alone is graded by its level.
CHANGE_GRADES = EVIDENCE_STEP | EVIDENCE_TREND

__all__ = [
    "CHANGE_GRADES",
    "LifecycleParams",
    "Observation",
    "PlaceState",
    "PlaceEvent",
    "Action",
    "PassHistory",
    "PlaceOutlook",
    "graded_next_limit",
    "place_outlook",
    "segment_trend",
    "advance_places",
    "severity_trend",
]


@dataclass(frozen=True)
class LifecycleParams:
    """Rules of the lifecycle (module docstring).

    Attributes
    ----------
    tolerance_m : float
        Widening of the extents when matching, m.
    min_confirmations : int
        Runs that must find a place before it is listed (≥ 1).
    confirm_tier : int
        A place of this tier or higher is listed at once.
    drop_after : int
        Consecutive covering runs without it after which a place is not active.
    tier_down_runs : int
        Consecutive confirming runs at a lower tier before the tier falls.
    hold_change : float
        Departure from its baseline (ln units) that holds a known place the run's tests did not flag.
    explain_days : float
        A place appearing this many days or fewer after an action over it is the action's effect.
    """

    tolerance_m: float = 10.0
    min_confirmations: int = 2
    confirm_tier: int = TIER_INTERVENTION
    drop_after: int = 2
    tier_down_runs: int = 2
    hold_change: float = 0.10
    explain_days: float = 60.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.explain_days) and self.explain_days >= 0):
            raise ValueError(f"explain_days: must be >= 0, got {self.explain_days!r}")
        if not (np.isfinite(self.hold_change) and self.hold_change > 0):
            raise ValueError(f"hold_change: must be > 0, got {self.hold_change!r}")
        if not (np.isfinite(self.tolerance_m) and self.tolerance_m >= 0):
            raise ValueError(f"tolerance_m: must be >= 0, got {self.tolerance_m!r}")
        for name in ("min_confirmations", "confirm_tier", "drop_after", "tier_down_runs"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}: must be >= 1, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class Observation:
    """What one run found of a place (extent, centroid and peak in m; level and change in ln units;
    evidence and agreeing-wheel bits as :class:`~app.analysis.condition.places.PlaceTable`)."""

    run_id: int
    day: float
    start_m: float
    end_m: float
    centre_m: float
    peak_m: float
    level: float
    change: float
    tier: int
    severity: float
    evidence: int
    wheels: int
    #: 1-σ of ``level``, ``change`` and ``severity`` (NaN: none stated; :mod:`~app.analysis.condition.run_places`)
    level_sd: float = float("nan")
    change_sd: float = float("nan")
    severity_sd: float = float("nan")


@dataclass
class PlaceState:
    """A known place (mutable: :func:`advance_places` updates it).

    Attributes
    ----------
    id : int
    direction : int
        +1 / −1.
    start_m, end_m, peak_m : float
        Extent and peak of the latest observation, m.
    cls : str or None
        Superstructure class at the peak (latest observation).
    baseline : float or None
        The index before the place appeared (ln units; None: first found without a step).
    explained_by : int or None
        The maintenance action whose effect the place is (never listed then).
    actions : list of int
        Maintenance actions over the place after it was first seen (linked to it).
    tier : int
        Current tier (with the falling rule of the module docstring).
    listed : bool
        Reached the listing rule once (stays True).
    active : bool
        Found by the latest run(s): not ``drop_after`` misses in a row.
    misses : int
        Consecutive covering runs that did not find it.
    lower_runs : int
        Consecutive confirming runs at a tier below ``tier``.
    observations : list of Observation
        Every run that found it, oldest first.
    """

    id: int
    direction: int
    start_m: float
    end_m: float
    peak_m: float
    cls: str | None = None
    baseline: float | None = None
    explained_by: int | None = None
    actions: list[int] = field(default_factory=list)
    tier: int = 0
    listed: bool = False
    active: bool = True
    misses: int = 0
    lower_runs: int = 0
    observations: list[Observation] = field(default_factory=list)

    @property
    def first_seen_day(self) -> float:
        return self.observations[0].day

    @property
    def last_confirmed_day(self) -> float:
        return self.observations[-1].day

    @property
    def confirmations(self) -> int:
        return len(self.observations)


@dataclass(frozen=True)
class PlaceEvent:
    """A change of a place that raises an alert.

    Attributes
    ----------
    place_id : int
    kind : {"new", "tier", "back", "repaired"}
    old_tier, new_tier : int
    action_id : int or None
        The maintenance action of a ``repaired`` event.
    """

    place_id: int
    kind: str
    old_tier: int
    new_tier: int
    action_id: int | None = None


@dataclass(frozen=True)
class Action:
    """A maintenance action of the line: id, extent on the aligned km axis (m), day, type."""

    id: int
    start_m: float
    end_m: float
    day: float
    kind: str = "tamping"


@dataclass(frozen=True)
class PassHistory:
    """A run's history as its **matched passes**, per segment of the run's places (``found.seg``): the
    values of the earlier runs that passed at a matched speed with the same vehicle
    (:func:`~app.analysis.condition.change.matched_passes`, the rule of the step test), mean over the wheels.

    On rough rails the index of a 10 m segment is the rails' response as much as the support's, and that
    response changes with the speed and the vehicle (measured on issue 33's line: one segment read −0.9 by
    one vehicle at 136 km/h, +0.5 by it at 91 km/h, −0.2 by the other vehicle at 135 km/h, each within
    ±0.1 run after run). A place's change is therefore read against its baseline **at the run's pass**
    (:meth:`baseline`), never against a baseline taken at another speed or by another vehicle.

    Attributes
    ----------
    values : numpy.ndarray
        (segments, runs) the matched passes' index, oldest first (NaN: no matched pass).
    days : numpy.ndarray
        (runs,) time of each history run, days.
    """

    values: np.ndarray
    days: np.ndarray

    def __post_init__(self) -> None:
        v, d = np.asarray(self.values, dtype=np.float64), np.asarray(self.days, dtype=np.float64)
        if v.ndim != 2 or d.shape != (v.shape[1],):
            raise ValueError(f"values, days: must be (segments, runs) and (runs,), got {v.shape} and {d.shape}")
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "days", d)

    @classmethod
    def of(cls, history: np.ndarray, history_speed: np.ndarray | None, speed: np.ndarray | None, days: np.ndarray,
           params: ChangeParams, *, history_vehicle: np.ndarray | None = None, vehicle: object = None,
           support_days: np.ndarray | None = None) -> PassHistory:
        """From a run's history per wheel: ``history`` and ``history_speed`` (W, S, R; speeds in m/s, None: every
        run at one speed), the run's ``speed`` (W, S), ``days`` (R,), the step test's ``params``
        (``speed_tolerance``, ``min_history``), the vehicles (R,) and the run's (None: one vehicle's) and the day
        of the latest action on the support of each segment (S,; NaN: none): the passes before it are not the
        track's since (:func:`~app.analysis.condition.interventions.since_actions`, as the tests see them)."""
        h = np.asarray(history, dtype=np.float64)
        if h.ndim != 3:
            raise ValueError(f"history: must be (wheels, segments, runs), got shape {h.shape}")
        if support_days is not None:
            h = since_actions(h, days, support_days)
        hv = np.ones(h.shape) if history_speed is None else np.asarray(history_speed, dtype=np.float64)
        v = np.ones(h.shape[:2]) if speed is None else np.asarray(speed, dtype=np.float64)
        if hv.shape != h.shape or v.shape != h.shape[:2]:
            raise ValueError(f"history_speed, speed: must be {h.shape} and {h.shape[:2]}, got {hv.shape} and {v.shape}")
        out = np.full(h.shape, np.nan)
        if h.shape[2]:
            for w in range(h.shape[0]):
                out[w] = matched_passes(h[w], hv[w], v[w], params, history_vehicle=history_vehicle,
                                        vehicle=vehicle).history
        return cls(mean_over_wheels(out), np.asarray(days, dtype=np.float64))

    def series(self, k: int, value: float, day: float) -> tuple[np.ndarray, np.ndarray]:
        """Segment ``k``'s matched passes and the run's own ``value`` on ``day``: days and index, oldest first
        (NaN where a history run is not a matched pass) — the series a developing place's trend is fitted on
        (:func:`segment_trend`)."""
        return np.append(self.days, float(day)), np.append(self.values[k], float(value))

    def baseline(self, k: int, first_seen_day: float) -> float | None:
        """A place's baseline at segment ``k`` for the run's pass: the median of its matched passes before the
        place was first seen, else (none in the history) its first matched pass since; None: no matched
        pass (its change cannot be read at this pass)."""
        v = self.values[k]
        ok = np.isfinite(v)
        before = ok & (self.days < first_seen_day)
        if before.any():
            return float(np.median(v[before]))
        return float(v[ok][0]) if ok.any() else None


def severity_trend(state: PlaceState, *, now_day: float | None = None, window_days: float | None = None) -> Trend:
    """Trend of the place's level in its own direction (``direction · level``, ln units) over its observations.

    ``window_days`` keeps only the observations of the last so many days (all by default).
    """
    days = np.array([o.day for o in state.observations], dtype=np.float64)
    vals = np.array([state.direction * o.level for o in state.observations], dtype=np.float64)
    if window_days is not None and days.size:
        keep = days >= days.max() - window_days
        days, vals = days[keep], vals[keep]
    return linear_trend(days, vals, now_day=now_day)


@dataclass(frozen=True)
class PlaceOutlook:
    """A place's trend, the next tier's limit and when it reaches it.

    Attributes
    ----------
    trend : Trend
        Of ``direction · level`` over the observations (ln units per year).
    next_limit : float
        The level limit of the tier above the place's (NaN at the immediate tier or without a class).
    projection : Projection
        Days from the last observation to ``next_limit`` (NaN: not projected).
    tendency : str
        ``new`` / ``growing`` / ``stable`` / ``shrinking``.
    """

    trend: Trend
    next_limit: float
    projection: Projection
    tendency: str


def place_outlook(state: PlaceState, levels: TierTable, *, window_days: float | None = None,
                  trend: Trend | None = None, changes: TierLimits | None = None) -> PlaceOutlook:
    """Trend, next limit, time to it and tendency of a place (the limits of its class in ``levels``).

    ``trend``: the severity's trend when fitted elsewhere (a developing place: over its segment's history,
    :func:`segment_trend`), else over the place's observations. ``changes``: the change limits; with them
    the time to the next tier is that of the tier's own grading (:func:`graded_next_limit`), else the
    time for the level to reach the next level limit as it is."""
    tr = trend if trend is not None else severity_trend(state, window_days=window_days)
    nxt = float(levels.limits_for(state.cls).next_limit(np.array([state.tier]))[0]) if state.cls is not None \
        else float("nan")
    reach = nxt if changes is None else graded_next_limit(state, levels, changes, tr.level)
    return PlaceOutlook(trend=tr, next_limit=nxt, projection=time_to_limit(tr, reach), tendency=tendency(tr))


def graded_next_limit(state: PlaceState, levels: TierTable, changes: TierLimits, severity_now: float) -> float:
    """The severity (``direction · level``, ln units) at which the place's tier rises to the next, as its
    observations are graded.

    A place's tier is the higher of its level's and its change's, each on its stated 1-σ
    (:func:`_graded`): the level graded in units of the healthy scatter at its pass
    (:func:`~app.analysis.condition.run_places.graded_level`: it reaches the next level limit ``L`` at
    ``L · √(1 + (sd / σ0)²)``), the change on its lower 1-σ bound (it reaches the next change limit ``C``
    at ``C + sd``); a size whose point value reaches a limit keeps at least the alert tier, so the alert
    tier comes at its limits as they are — for a place without a graded change (first found by its level
    alone, graded as its run graded it) at its level graded, as every tier. A trend moves level and change
    alike, so the next tier comes at the nearer of the two, from the last observation's 1-σ (a stated 1-σ as
    it is now). Projecting the level to the level limit as it is read a place on rough rails (1-σ 0.64) as
    at its next limit today while its tier lay a tier below; on smooth rails (1-σ 0.056) a limit of 0.25
    graded is reached at 0.31.

    Parameters
    ----------
    state : PlaceState
        The place (class, tier, direction and its last observation's level, change and 1-σ).
    levels : TierTable
        The level limits by class.
    changes : TierLimits
        The change limits.
    severity_now : float
        The severity the trend stands at now (``Trend.level``), ln units.

    Returns
    -------
    float
        The severity to reach, ln units (NaN at the immediate tier, or with no limit above).
    """
    if not state.observations:
        return float("nan")
    last = state.observations[-1]
    tier = np.array([state.tier])
    # the change grades the tier where the reading had a baseline (advance_places: the place's, or its
    # matched passes' once known) or its run's evidence grades by the change; a place first found by its
    # level alone is graded as its run graded it (find_places: its level graded on the 1-σ for every tier)
    has_change = bool(np.isfinite(last.change) and (state.baseline is not None or last.evidence & CHANGE_GRADES
                                                    or len(state.observations) > 1))
    graded = state.tier >= TIER_ALERT or not has_change
    routes = []
    if state.cls is not None:
        limits = levels.limits_for(state.cls)
        nxt = float(limits.next_limit(tier)[0])
        if np.isfinite(nxt):
            # graded_level(1, sd, alert) = 1 / √(1 + (sd/σ0)²)
            routes.append(nxt / float(graded_level(1.0, last.level_sd, limits.alert)) if graded else nxt)
    c_next = float(changes.next_limit(tier)[0])
    if np.isfinite(c_next) and has_change and np.isfinite(severity_now):
        sd = last.change_sd if graded and np.isfinite(last.change_sd) else 0.0
        routes.append(severity_now + c_next + sd - state.direction * last.change)
    return min(routes) if routes else float("nan")


def segment_trend(state: PlaceState, days: np.ndarray, index: np.ndarray, *, now_day: float) -> Trend:
    """The trend of a developing place's severity over every run of its peak segment's history.

    A place found by the trend test grows steadily: its history is what the test fitted (every run of the
    window, also those before the place reached a limit and was first found), while its own observations
    are the few runs since — too few for a significant rate, so no time to its next limit (measured: the
    demo's place developing at −1 ln unit a year read *stable*).

    Parameters
    ----------
    state : PlaceState
    days : numpy.ndarray
        Days of the runs (the history and the run), any origin shared with ``now_day``.
    index : numpy.ndarray
        The index at the place's peak segment in those runs, ln units (NaN: none).
    now_day : float
    """
    return linear_trend(np.asarray(days, dtype=np.float64), state.direction * np.asarray(index, dtype=np.float64),
                        now_day=now_day)


def _apply_tier(state: PlaceState, new_tier: int, params: LifecycleParams, events: list[PlaceEvent]) -> None:
    """The tier rises at once and falls after ``tier_down_runs`` lower runs; events for a listed place."""
    if new_tier > state.tier:
        old = state.tier
        state.tier, state.lower_runs = new_tier, 0
        if state.listed:
            events.append(PlaceEvent(state.id, "tier", old, state.tier))
    elif new_tier < state.tier:
        state.lower_runs += 1
        if state.lower_runs >= params.tier_down_runs:
            old = state.tier
            state.tier, state.lower_runs = new_tier, 0
            if state.listed:
                events.append(PlaceEvent(state.id, "tier", old, state.tier))
    else:
        state.lower_runs = 0


def _graded(place_params: PlaceParams | None, cls: str | None, level: float, change: float,
            direction: int, tier: int, level_sd: float = float("nan"), change_sd: float = float("nan")) -> int:
    """The tier of an observation from its level and its change against the place's baseline, each on its
    lower 1-σ bound where a 1-σ is stated (a graded size of tier ≥ 1 keeps at least the alert tier)."""
    if place_params is None:
        return tier
    if not np.isfinite(change):
        return tier

    def on_bound(limits, size: float, low_size: float) -> int:
        point = int(limits.grade(np.array([size]))[0])
        low = int(limits.grade(np.array([low_size]))[0])
        return max(min(point, low), 1) if point >= 1 else point

    if cls is not None:
        limits = place_params.levels.limits_for(cls)
        lt = on_bound(limits, abs(level), float(graded_level(level, level_sd, limits.alert)))
    else:
        lt = 0
    size = direction * change
    ct = on_bound(place_params.changes, size, size - (change_sd if np.isfinite(change_sd) else 0.0))
    return max(lt, ct)


def advance_places(
    known: list[PlaceState],
    found: RunPlaces,
    *,
    run_id: int,
    day: float,
    covered_m: tuple[float, float],
    params: LifecycleParams,
    next_id: int,
    place_params: PlaceParams | None = None,
    actions: Sequence[Action] = (),
    passes: PassHistory | None = None,
) -> tuple[list[PlaceEvent], list[int], int]:
    """Apply one run to the known places (in place) and add its new ones.

    Parameters
    ----------
    known : list of PlaceState
        The line's known places; updated, and new places appended.
    found : RunPlaces
        The run's places (and its per-segment index, for the places it did not flag).
    run_id : int
    day : float
        Time of the run, days.
    covered_m : (float, float)
        Extent the run has data for, m (known places inside it and not found are held or missed).
    params : LifecycleParams
    next_id : int
        Id of the next new place.
    place_params : PlaceParams, optional
        The limits: with them a known place's tier is graded on its change against its baseline
        (else the run's tier stands).
    actions : sequence of Action
        The line's maintenance actions (those after ``day`` are ignored).
    passes : PassHistory, optional
        The run's history as its matched passes on ``found.seg``: a known place's change is read against
        its baseline at the run's pass (:meth:`PassHistory.baseline`; where it has none, the run's own step
        stands). Without it, against the place's one baseline.

    Returns
    -------
    events : list of PlaceEvent
    ids : list of int
        The place id of each of the run's places (in ``found`` order).
    next_id : int
    """
    if not isinstance(params, LifecycleParams):
        raise TypeError("params: must be a LifecycleParams")
    lo, hi = covered_m
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
        raise ValueError(f"covered_m: must be finite with from <= to, got {covered_m!r}")
    if passes is not None and passes.values.shape[0] != found.seg.size:
        raise ValueError(f"passes: must have one row per segment of found ({found.seg.size}), "
                         f"got {passes.values.shape[0]}")
    acts = [a for a in actions if a.day <= day]
    a_start = np.array([a.start_m for a in acts], dtype=np.float64)
    a_end = np.array([a.end_m for a in acts], dtype=np.float64)
    p = found.places
    gap_m = place_params.gap_m if place_params is not None else params.tolerance_m
    # a place merged into another (a piece of one defect, :func:`_merge_pieces`) is part of it: not matched, not
    # held on its own (it would come back as a place of its own, with a ``back`` alert, run after run)
    pieces = _pieces(known, gap_m)
    match = match_places(p.start_m, p.end_m, p.direction,
                         np.array([k.start_m for k in known]), np.array([k.end_m for k in known]),
                         np.array([0 if j in pieces else k.direction for j, k in enumerate(known)], dtype=np.int64),
                         tolerance_m=params.tolerance_m)
    events: list[PlaceEvent] = []
    ids: list[int] = []
    matched = set()
    for i in range(len(p)):
        level, change = float(found.level[i]), float(found.change[i])
        j = int(match.known[i])
        state = known[j] if j >= 0 else None
        peak_m, cls = float(found.peak_m[i]), found.cls[i]
        level_sd, change_sd, severity_sd = (float(a[i]) if a.size == len(p) else float("nan")
                                            for a in (found.level_sd, found.change_sd, found.severity_sd))
        severity = float(found.severity[i])
        if state is not None and state.baseline is not None:
            # a known place is read where it departs most from its baseline on its own ground (the run's extent
            # within the place's known one), as a held place is: the run's own peak is where the run's step
            # test fired against each segment's rolling history, which a developing place has absorbed (the
            # demo's place developing at −1 ln unit a year was read at its taper's edge, −0.05 from its
            # baseline, and fell to watch with a tier-down alert)
            own_from, own_to = max(float(p.start_m[i]), state.start_m), min(float(p.end_m[i]), state.end_m)
            k, base = _reading(state, found, own_from, own_to, passes) if own_from < own_to \
                else (None, state.baseline if passes is None else None)
            if k is not None:
                level, peak_m, cls = float(found.seg_index[k]), (float(found.seg[k]) + 0.5) * found.segment_m, \
                    found.seg_class[k]
                if found.seg_level_sd.size == found.seg.size:
                    level_sd = float(found.seg_level_sd[k])
            if base is not None:
                change = level - base
                # the change against the baseline is the reading's level less a constant: its 1-σ is the level's
                # (not the run's step test's at its own peak, another segment against another history)
                change_sd = level_sd
                severity, sev_sd = _severity(place_params, cls, level, change, level_sd, severity)
                severity_sd = sev_sd if place_params is not None else severity_sd
            if base is None or _receding(place_params, state, base, cls, level, level_sd):
                # no baseline at the run's pass (the place never passed so before: its change there is the run's
                # own step's), or the baseline was an anomaly of the other side and the reading is none of this
                # side (the change is that anomaly receding towards the typical track): graded as the run graded it
                change, change_sd = float(found.change[i]), float(found.change_sd[i]) \
                    if found.change_sd.size == len(p) else float("nan")
                severity = float(found.severity[i])
                base = None
        else:
            base = None
        # the change grades a place against its baseline at the run's pass, or where the run's step test fired
        graded_change = change if base is not None or (p.evidence[i] & CHANGE_GRADES) else float("nan")
        tier = _graded(place_params, cls, level, graded_change, int(p.direction[i]), int(found.tier[i]),
                       level_sd, change_sd)
        obs = Observation(run_id=run_id, day=float(day), start_m=float(p.start_m[i]), end_m=float(p.end_m[i]),
                          centre_m=float(p.centre_m[i]), peak_m=peak_m, level=level, change=change,
                          tier=tier, severity=severity, evidence=int(p.evidence[i]),
                          wheels=int(p.wheels[i]), level_sd=level_sd, change_sd=change_sd, severity_sd=severity_sd)
        if state is None:
            state = PlaceState(id=next_id, direction=int(p.direction[i]), start_m=obs.start_m, end_m=obs.end_m,
                               peak_m=obs.peak_m, cls=found.cls[i], tier=obs.tier,
                               baseline=level - change if np.isfinite(change) and (p.evidence[i] & EVIDENCE_STEP)
                               else None)
            next_id += 1
            known.append(state)
            was_active = True
            recent = [acts[k] for k in covering_actions(obs.start_m, obs.end_m, a_start, a_end)
                      if 0.0 <= day - acts[k].day <= params.explain_days]
            if recent:
                state.explained_by = max(recent, key=lambda a: a.day).id
        else:
            matched.add(j)
            was_active = state.active
            own = (state.start_m, state.end_m)
            state.start_m, state.end_m, state.peak_m = obs.start_m, obs.end_m, obs.peak_m
            state.cls = cls
            if state.baseline is None and np.isfinite(found.change[i]) and (p.evidence[i] & EVIDENCE_STEP) \
                    and own[0] <= float(found.peak_m[i]) < own[1]:
                # a baseline is the index of the place's own ground before it changed: from a step at a segment
                # of its known extent, not at a neighbour the run's place reaches (measured: a lasting +0.57 place
                # given the baseline of the segment 20 m beside it, −0.50, read a +1.0 change "immediate" for
                # 18 runs)
                state.baseline = level - float(found.change[i])
            _apply_tier(state, obs.tier, params, events)
        _confirm(state, obs, was_active, params, events)
        ids.append(state.id)
    for j, state in enumerate(known):
        if state.explained_by is None and acts:
            for k in covering_actions(state.start_m, state.end_m, a_start, a_end):
                if acts[k].day > state.first_seen_day and acts[k].id not in state.actions:
                    state.actions.append(acts[k].id)
        if j in matched or state.observations[-1].run_id == run_id or j in pieces:
            continue
        if not (lo <= state.start_m and state.end_m <= hi) or not _observed(state, found):
            continue
        held = _held(state, found, run_id, day, params, place_params, passes)
        if held is not None:
            was_active = state.active
            _apply_tier(state, held.tier, params, events)
            _confirm(state, held, was_active, params, events)
            continue
        state.misses += 1
        repair = [a for a in acts if a.id in state.actions and state.last_confirmed_day < a.day <= day]
        if repair and state.active and state.explained_by is None:
            state.active = False
            if state.listed:
                events.append(PlaceEvent(state.id, "repaired", state.tier, state.tier,
                                         action_id=max(repair, key=lambda a: a.day).id))
        elif state.misses >= params.drop_after:
            state.active = False
    _merge_pieces(known, run_id, gap_m, params)
    # a candidate never confirmed is forgotten (an action's effect is kept as its record)
    known[:] = [k for k in known if k.listed or k.active or k.explained_by is not None]
    return events, ids, next_id


def _confirm(state: PlaceState, obs: Observation, was_active: bool, params: LifecycleParams,
             events: list[PlaceEvent]) -> None:
    state.observations.append(obs)
    state.misses = 0
    state.active = True
    if state.listed and not was_active:
        events.append(PlaceEvent(state.id, "back", state.tier, state.tier))
    if state.explained_by is not None:
        return
    if not state.listed and (state.confirmations >= params.min_confirmations or state.tier >= params.confirm_tier):
        state.listed = True
        events.append(PlaceEvent(state.id, "new", 0, state.tier))


def _observed(state: PlaceState, found: RunPlaces) -> bool:
    """The run has an index over the place's extent (where it has none — no reference curve at the speed
    it passed there, no valid bins — it could not see the place, and does not miss it)."""
    if found.seg.size == 0:
        return False
    a = np.searchsorted(found.seg, int(np.floor(state.start_m / found.segment_m)), side="left")
    b = np.searchsorted(found.seg, int(np.ceil(state.end_m / found.segment_m)), side="left")
    return bool(np.isfinite(found.seg_index[a:b]).any())


def _worst_segment(direction: int, found: RunPlaces, start_m: float, end_m: float) -> int | None:
    """The run's segment over ``start_m … end_m`` whose index lies furthest in ``direction`` (position into
    ``found.seg``; None: no index there). Against a place's one baseline that is also the segment departing
    most from it."""
    if found.seg.size == 0:
        return None
    a = int(np.searchsorted(found.seg, int(np.floor(start_m / found.segment_m)), side="left"))
    b = int(np.searchsorted(found.seg, int(np.ceil(end_m / found.segment_m)), side="left"))
    vals = found.seg_index[a:b]
    if vals.size == 0 or not np.isfinite(vals).any():
        return None
    return a + int(np.argmax(direction * np.nan_to_num(vals, nan=-direction * np.inf)))


def _reading(state: PlaceState, found: RunPlaces, start_m: float, end_m: float,
             passes: PassHistory | None) -> tuple[int | None, float | None]:
    """Where a run reads a known place over ``start_m … end_m`` and the baseline it is read against: the
    segment departing most from its baseline at the run's pass (:meth:`PassHistory.baseline`) and that
    baseline; without ``passes`` the segment furthest in the place's direction and the place's one baseline.
    (None, None): no index there; (k, None): no segment with a baseline at the run's pass."""
    if passes is None:
        return _worst_segment(state.direction, found, start_m, end_m), state.baseline
    if found.seg.size == 0:
        return None, None
    a = int(np.searchsorted(found.seg, int(np.floor(start_m / found.segment_m)), side="left"))
    b = int(np.searchsorted(found.seg, int(np.ceil(end_m / found.segment_m)), side="left"))
    best: tuple[float, int, float] | None = None
    for k in range(a, b):
        level = float(found.seg_index[k])
        base = passes.baseline(k, state.first_seen_day) if np.isfinite(level) else None
        if base is not None and (best is None or state.direction * (level - base) > best[0]):
            best = (state.direction * (level - base), k, base)
    if best is None:
        return _worst_segment(state.direction, found, start_m, end_m), None
    return best[1], best[2]


def _severity(place_params: PlaceParams | None, cls: str | None, level: float, change: float, level_sd: float,
              default: float) -> tuple[float, float]:
    """Severity (the larger of level and change in units of their alert limits) and its 1-σ (the level's share;
    NaN where the change sets it) of a reading against a place's baseline; ``default`` without limits."""
    if place_params is None:
        return default, float("nan")
    lvl_alert = place_params.levels.limits_for(cls).alert if cls is not None else np.inf
    chg_alert = place_params.changes.alert
    by_level, by_change = abs(level) / lvl_alert, abs(change) / chg_alert
    return float(max(by_level, by_change)), (level_sd / lvl_alert if by_level >= by_change else float("nan"))


def _held(state: PlaceState, found: RunPlaces, run_id: int, day: float, params: LifecycleParams,
          place_params: PlaceParams | None, passes: PassHistory | None = None) -> Observation | None:
    """The observation that holds a known place the run did not flag (None: it is back at its baseline)."""
    if state.baseline is None:
        return None
    k, base = _reading(state, found, state.start_m, state.end_m, passes)
    if k is None or base is None:
        return None
    level = float(found.seg_index[k])
    change = level - base
    cls = found.seg_class[k]
    level_sd = float(found.seg_level_sd[k]) if found.seg_level_sd.size == found.seg.size else float("nan")
    # held while the departure from the baseline, less the reading's 1-σ, reaches hold_change: on rough rail one
    # pass's 10 m level is uncertain by 0.2–0.5 ln units, and a place held on its point reading was held by
    # noise run after run (measured: one run's −0.93 held for 5 runs at −0.11 ± 0.39, "immediate")
    if not state.direction * change - (level_sd if np.isfinite(level_sd) else 0.0) >= params.hold_change:
        return None
    if _receding(place_params, state, base, cls, level, level_sd):
        return None
    tier = _graded(place_params, cls, level, change, state.direction, state.tier, level_sd, level_sd)
    severity, severity_sd = _severity(place_params, cls, level, change, level_sd, 0.0)
    peak = (float(found.seg[k]) + 0.5) * found.segment_m
    # held, not found: the place keeps its extent and the centre the run that last found it located
    return Observation(run_id=run_id, day=float(day), start_m=state.start_m, end_m=state.end_m,
                       centre_m=state.observations[-1].centre_m, peak_m=peak, level=level, change=change, tier=tier,
                       severity=severity, evidence=EVIDENCE_STEP, wheels=0, level_sd=level_sd, change_sd=level_sd,
                       severity_sd=severity_sd)


def _receding(place_params: PlaceParams | None, state: PlaceState, base: float | None, cls: str | None,
              level: float, level_sd: float) -> bool:
    """The place's baseline was an anomaly of the other side (its size reaches the class's alert limit) and the
    reading is no anomaly of the place's side (its level, graded on its 1-σ by :func:`~app.analysis.condition.run_places.graded_level`, below the alert limit): the change
    against the baseline is that former anomaly receding towards the typical track — a hard place softening, a
    ground surface running in — not a place of this side (the rule of
    :func:`~app.analysis.condition.run_places.find_places` for a step back from a former anomaly, against the
    place's own baseline). Measured: a place with a baseline of +0.45 read at −0.06 ± 0.09 was graded on its
    change of −0.51, "immediate"."""
    if place_params is None or cls is None or base is None or not np.isfinite(level):
        return False
    alert = place_params.levels.limits_for(cls).alert
    was_other = state.direction * base <= -alert
    of_side = state.direction * level > 0 and float(graded_level(level, level_sd, alert)) >= alert
    return bool(was_other and not of_side)


def _near(a: PlaceState, b: PlaceState, gap_m: float) -> bool:
    """Two places of one direction whose extents lie within ``gap_m`` of each other (the merge rule of a run's
    segments, :func:`~app.analysis.condition.places.merge_places`)."""
    return a.direction == b.direction and max(a.start_m, b.start_m) - min(a.end_m, b.end_m) <= gap_m + 1e-9


def _pieces(known: list[PlaceState], gap_m: float) -> set[int]:
    """Positions of the inactive places that lie within ``gap_m`` of an active place of their direction and
    within its extent so widened: pieces merged into it (:func:`_merge_pieces`)."""
    active = [k for k in known if k.active and k.explained_by is None]
    return {j for j, k in enumerate(known) if not k.active and k.explained_by is None
            and any(a.start_m - gap_m <= k.start_m and k.end_m <= a.end_m + gap_m and _near(a, k, gap_m)
                    for a in active)}


def _merge_pieces(known: list[PlaceState], run_id: int, gap_m: float, params: LifecycleParams) -> None:
    """One defect, one place: active places of one direction within ``gap_m`` of each other (by the rule that
    merges a run's segments into one place) are merged into one — the one this run observed (found before
    held; a listed one before one that is not), else the oldest — over the union of their extents, at the highest of their tiers, listed if any was.
    The others stay as its pieces (inactive, their observations kept; :func:`_pieces`). Measured on issue 33's
    real line: a change of 20–30 m was split into two or three places, each held on its own 10 m reading."""
    def rank(k: PlaceState) -> tuple[bool, int, float, int]:
        last = k.observations[-1]
        seen = 0 if last.run_id == run_id and last.wheels else 1 if last.run_id == run_id else 2
        return not k.listed, seen, k.first_seen_day, k.id

    live = sorted((k for k in known if k.active and k.explained_by is None), key=lambda k: (k.direction, k.start_m))
    groups: list[list[PlaceState]] = []
    for k in live:
        g = groups[-1] if groups else []
        if g and g[0].direction == k.direction and k.start_m - max(m.end_m for m in g) <= gap_m + 1e-9:
            g.append(k)
        else:
            groups.append([k])
    for g in groups:
        if len(g) < 2:
            continue
        keep = min(g, key=rank)
        keep.start_m, keep.end_m = min(k.start_m for k in g), max(k.end_m for k in g)
        keep.tier = max(k.tier for k in g)
        keep.listed = any(k.listed for k in g)
        if keep.baseline is None:
            keep.baseline = next((k.baseline for k in sorted(g, key=rank) if k.baseline is not None), None)
        for k in g:
            if k is not keep:
                k.active, k.misses = False, max(k.misses, params.drop_after)
