"""The lifecycle of places over runs: identity, confirmation, tier changes and the alerts they raise.

A run's places (:func:`~app.analysis.condition.run_places.find_places`) are
matched to the known places of the line (:func:`~app.analysis.condition.identity.match_places`,
every known place whatever its workflow status, so a place that comes back
after it was marked fixed keeps its id and history). Then:

* a known place found again is **confirmed** by the run: its extent becomes
  today's, its observation (day, level, change, tier) is added; a place not found
  by a run that covered its extent is **missed** by it (``misses`` counts the
  consecutive ones), and after ``drop_after`` misses it is no longer
  **active** (not on the list until found again; a place never listed is
  then forgotten);
* a place is **listed** (on the work list, and alerted) once ``min_confirmations``
  runs found it — a single run's exceedance that the next run does not repeat
  is noise of that run — or at once when its tier reaches ``confirm_tier``
  (what needs action now is not held back by a run);
* its **tier** rises at once; it falls only when ``tier_down_runs`` consecutive
  confirming runs put it lower (no alert ping-pong for a place at a limit).

Events (:class:`PlaceEvent`) — ``new`` when a place becomes listed, ``tier``
when a listed place's tier changes, ``back`` when an inactive place is found
again — are what alerts are sent for; nothing else in a run raises one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from app.analysis.condition.identity import match_places
from app.analysis.condition.outlook import Trend, linear_trend
from app.analysis.condition.run_places import RunPlaces
from app.analysis.condition.tiers import TIER_INTERVENTION

__all__ = ["LifecycleParams", "Observation", "PlaceState", "PlaceEvent", "advance_places", "severity_trend"]


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
    """

    tolerance_m: float = 10.0
    min_confirmations: int = 2
    confirm_tier: int = TIER_INTERVENTION
    drop_after: int = 2
    tier_down_runs: int = 2

    def __post_init__(self) -> None:
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
    kind : {"new", "tier", "back"}
    old_tier, new_tier : int
    """

    place_id: int
    kind: str
    old_tier: int
    new_tier: int


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


def advance_places(
    known: list[PlaceState],
    found: RunPlaces,
    *,
    run_id: int,
    day: float,
    covered_m: tuple[float, float],
    params: LifecycleParams,
    next_id: int,
) -> tuple[list[PlaceEvent], list[int], int]:
    """Apply one run to the known places (in place) and add its new ones.

    Parameters
    ----------
    known : list of PlaceState
        The line's known places; updated, and new places appended.
    found : RunPlaces
        The run's places.
    run_id : int
    day : float
        Time of the run, days.
    covered_m : (float, float)
        Extent the run has data for, m (known places inside it and not found are missed).
    params : LifecycleParams
    next_id : int
        Id of the next new place.

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
    p = found.places
    match = match_places(p.start_m, p.end_m, p.direction,
                         np.array([k.start_m for k in known]), np.array([k.end_m for k in known]),
                         np.array([k.direction for k in known], dtype=np.int64), tolerance_m=params.tolerance_m)
    events: list[PlaceEvent] = []
    ids: list[int] = []
    matched = set()
    for i in range(len(p)):
        obs = Observation(run_id=run_id, day=float(day), start_m=float(p.start_m[i]), end_m=float(p.end_m[i]),
                          centre_m=float(p.centre_m[i]), peak_m=float(found.peak_m[i]), level=float(found.level[i]), change=float(found.change[i]),
                          tier=int(found.tier[i]), severity=float(found.severity[i]), evidence=int(p.evidence[i]),
                          wheels=int(p.wheels[i]))
        j = int(match.known[i])
        if j < 0:
            state = PlaceState(id=next_id, direction=int(p.direction[i]), start_m=obs.start_m, end_m=obs.end_m,
                               peak_m=obs.peak_m, cls=found.cls[i], tier=obs.tier)
            next_id += 1
            known.append(state)
            was_active = True
        else:
            state = known[j]
            matched.add(j)
            was_active = state.active
            state.start_m, state.end_m, state.peak_m = obs.start_m, obs.end_m, obs.peak_m
            state.cls = found.cls[i]
            # the tier rises at once and falls after tier_down_runs lower runs
            if obs.tier > state.tier:
                old = state.tier
                state.tier, state.lower_runs = obs.tier, 0
                if state.listed:
                    events.append(PlaceEvent(state.id, "tier", old, state.tier))
            elif obs.tier < state.tier:
                state.lower_runs += 1
                if state.lower_runs >= params.tier_down_runs:
                    old = state.tier
                    state.tier, state.lower_runs = obs.tier, 0
                    if state.listed:
                        events.append(PlaceEvent(state.id, "tier", old, state.tier))
            else:
                state.lower_runs = 0
        state.observations.append(obs)
        state.misses = 0
        state.active = True
        if state.listed and not was_active:
            events.append(PlaceEvent(state.id, "back", state.tier, state.tier))
        if not state.listed and (state.confirmations >= params.min_confirmations or state.tier >= params.confirm_tier):
            state.listed = True
            events.append(PlaceEvent(state.id, "new", 0, state.tier))
        ids.append(state.id)
    for j, state in enumerate(known):
        if j in matched or state.observations[-1].run_id == run_id:
            continue
        if lo <= state.start_m and state.end_m <= hi:
            state.misses += 1
            if state.misses >= params.drop_after:
                state.active = False
    known[:] = [k for k in known if k.listed or k.active]  # a candidate never confirmed is forgotten
    return events, ids, next_id
