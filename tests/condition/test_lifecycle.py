"""The lifecycle of places over runs on synthetic truth: identity with alignment residuals, first seen /
last confirmed / runs confirming, growing / stable / shrinking, a repaired place that comes back with its
history, maintenance actions, alerts only for new places and tier changes; the outlook of a place; an
action's effect from the extent against its surroundings."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
import pytest

from app.analysis.condition.extent_level import extent_level, surroundings_level
from app.analysis.condition.lifecycle import (
    Action,
    LifecycleParams,
    Observation,
    PlaceEvent,
    PlaceState,
    _graded,
    advance_places,
    graded_next_limit,
    place_outlook,
    segment_trend,
)
from app.analysis.condition.maintenance_effect import action_effect
from app.analysis.condition.places import EVIDENCE_ANOMALY, EVIDENCE_STEP
from app.analysis.condition.run_places import find_places
from app.analysis.condition.tiers import TIER_ALERT, TIER_IMMEDIATE, TIER_INTERVENTION
from tests.condition.places_support import COVERED, PARAMS, SEG, box, runs, track

CLS = np.full(SEG.size, "b91", dtype=object)
EVERY = 14.0  # days between runs


def _history(seed: int, n: int, extra: Callable[[int], np.ndarray], *, natural: float = 0.3) -> np.ndarray:
    """(W, S, n) index of ``n`` runs of one line whose track is its own variation + ``extra(run)``."""
    return runs(np.random.default_rng(seed), track(np.random.default_rng(seed + 1000)) * natural, n, extra)


def _advance(index: np.ndarray, *, first: int = 5, actions: Sequence[Action] = (),
             covered: Callable[[int], tuple[float, float]] = lambda r: COVERED,
             ) -> tuple[list[PlaceState], dict[int, list[PlaceEvent]], dict[int, list[int]]]:
    """Run the lifecycle over runs ``first …`` (each run's history: the runs before it)."""
    days = np.arange(index.shape[2]) * EVERY
    known: list[PlaceState] = []
    next_id, events, ids = 1, {}, {}
    for r in range(first, index.shape[2]):
        rp = find_places(SEG, index[:, :, r], index[:, :, :r], days[:r], days[r], CLS, segment_m=10.0, params=PARAMS)
        events[r], ids[r], next_id = advance_places(known, rp, run_id=r, day=days[r], covered_m=covered(r),
                                                    params=LifecycleParams(), next_id=next_id, place_params=PARAMS,
                                                    actions=actions)
    return known, events, ids


def _kinds(events: dict[int, list[PlaceEvent]]) -> list[tuple[int, str, int]]:
    return [(r, e.kind, e.place_id) for r, evs in events.items() for e in evs]


# --- identity, first seen, last confirmed, runs confirming -------------------------------------------


def test_places_keep_their_id_through_alignment_residuals_growth_and_a_run_that_does_not_cover_them():
    rng = np.random.default_rng(21)
    offset = rng.normal(0, 2.0, 16)  # each run's alignment residual, m

    def extra(r: int) -> np.ndarray:
        o = offset[r]
        grow = 20.0 if r >= 10 else 0.0  # the soft place grows by 20 m from run 10 on
        return box(11_000.0 + o, 11_030.0 + o, 0.33) + box(11_080.0 + o, 11_110.0 + o + grow, -0.33)

    index = _history(22, 16, extra)
    index[:, SEG < 1200, 12] = np.nan  # run 12 covers km 12–13 only
    known, events, ids = _advance(index, covered=lambda r: (12_000.0, 13_000.0) if r == 12 else COVERED)
    assert [k.id for k in known] == [1, 2]
    hard, soft = known
    assert (hard.direction, soft.direction) == (1, -1)
    assert all(ids[r] == [] if r == 12 else ids[r] == [1, 2] for r in ids)
    # listed on the 2nd run that found them; then only the growth's tier (its new 20 m changed by −28 %)
    kinds = _kinds(events)
    assert kinds[:2] == [(6, "new", 1), (6, "new", 2)]
    assert all(kind == "tier" and pid == 2 and r >= 10 for r, kind, pid in kinds[2:])
    for k in known:
        assert k.confirmations == 10  # runs 5 … 15 but 12
        assert k.first_seen_day == 5 * EVERY and k.last_confirmed_day == 15 * EVERY
        assert [o.run_id for o in k.observations] == [5, 6, 7, 8, 9, 10, 11, 13, 14, 15]
        assert k.misses == 0 and k.active and k.listed
    assert abs(hard.observations[-1].centre_m - (11_015.0 + offset[15])) < 5.0
    assert soft.end_m >= 11_120.0  # its latest extent is the grown one
    assert abs(soft.observations[-1].centre_m - (11_105.0 + offset[15])) < 5.0


def test_runs_without_an_index_over_a_place_do_not_miss_it():
    spot = box(12_500.0, 12_530.0, 0.45)  # an intervention-tier hard place, listed at once
    index = _history(23, 12, lambda r: spot)
    # runs 7 and 8 passed km 12.4–12.7 at a speed without a reference curve: no index there
    index[:, (SEG >= 1240) & (SEG < 1270), 7:9] = np.nan
    known, events, ids = _advance(index)
    assert [k.id for k in known] == [1] and known[0].active and known[0].misses == 0
    assert _kinds(events) == [(5, "new", 1)]  # no 'back' after the runs that could not see it
    assert ids[7] == ids[8] == [] and known[0].confirmations == 5
    # a run with an index there that does not find it misses it
    index[:, :, 9:] -= spot[None, :, None]  # repaired from run 9 on (no action recorded)
    known, events, _ = _advance(index)
    assert not known[0].active and _kinds(events) == [(5, "new", 1)]


# --- growing / stable / shrinking ---------------------------------------------------------------------


def test_growing_stable_and_shrinking_places_and_a_shrinking_hard_place_is_not_a_new_soft_one():
    grow, stay, shrink = box(11_000.0, 11_030.0, 1.0), box(11_500.0, 11_530.0, 1.0), box(12_000.0, 12_030.0, 1.0)
    index = _history(5, 14, lambda r: grow * (0.30 + 0.02 * r) + stay * 0.32 + shrink * (0.58 - 0.02 * r),
                     natural=0.0)
    known, events, ids = _advance(index)
    # one place each, all hard: the shrinking one's step back towards typical track is no soft place
    assert [(k.id, k.direction, k.start_m) for k in known] == [(1, 1, 11_000.0), (2, 1, 11_500.0), (3, 1, 12_000.0)]
    assert all(i == [1, 2, 3] for i in ids.values())
    out = {k.id: place_outlook(k, PARAMS.levels) for k in known}
    assert [out[i].tendency for i in (1, 2, 3)] == ["growing", "stable", "shrinking"]
    # truth: ±0.02 per 14 days = ±0.52 a year (the level at the peak segment: the run's level and the
    # noise of the segment picked ride on it)
    truth = 0.02 / EVERY * 365.25
    assert out[1].trend.rate_per_year == pytest.approx(truth, rel=0.25)
    assert out[3].trend.rate_per_year == pytest.approx(-truth, rel=0.25)
    assert out[2].trend.low_per_year <= 0.0 <= out[2].trend.high_per_year
    # only the growing place has a date: it reaches the immediate-action limit 0.625 around run 16.25
    assert math.isnan(out[2].projection.days) and math.isnan(out[3].projection.days)
    assert known[0].tier == TIER_INTERVENTION and out[1].next_limit == 0.625
    days_truth = (0.625 - (0.30 + 0.02 * 13)) / 0.02 * EVERY
    assert 0.4 * days_truth < out[1].projection.days < 2.0 * days_truth
    assert out[1].projection.days == pytest.approx((0.625 - out[1].trend.level) / out[1].trend.rate_per_year * 365.25)
    # alerts: each place once when listed, then tier changes only (the shrinking one falls to alert)
    kinds = _kinds(events)
    assert sorted(k for k in kinds if k[1] == "new") == [(5, "new", 1), (5, "new", 3), (6, "new", 2)]
    assert {k[1] for k in kinds} <= {"new", "tier"}
    assert [(e.old_tier, e.new_tier) for evs in events.values() for e in evs if e.place_id == 3 and e.kind == "tier"] \
        == [(TIER_INTERVENTION, TIER_ALERT)]


# --- a repaired place that comes back; actions that do and do not repair -----------------------------


def test_a_tamping_repairs_a_place_that_later_comes_back_with_its_id_and_history():
    step = box(12_000.0, 12_020.0, math.log(1.25))  # +25 % from run 6; repaired on day 147; back from run 15
    tamping = Action(id=7, start_m=11_950.0, end_m=12_100.0, day=147.0)
    index = _history(31, 19, lambda r: step if 6 <= r <= 10 or r >= 15 else 0.0 * step)
    known, events, ids = _advance(index, actions=[tamping])
    assert [k.id for k in known] == [1]
    k = known[0]
    assert _kinds(events) == [(7, "new", 1), (11, "repaired", 1), (15, "back", 1)]
    repaired = next(e for e in events[11] if e.kind == "repaired")
    assert repaired.action_id == 7
    assert k.actions == [7] and k.explained_by is None
    # its history: the runs before the repair and after its return, the first seen day unchanged
    assert [o.run_id for o in k.observations] == [6, 7, 8, 9, 10, 15, 16, 17, 18]
    assert k.first_seen_day == 6 * EVERY and k.last_confirmed_day == 18 * EVERY
    assert k.active and k.listed and k.baseline is not None
    assert all(o.evidence & EVIDENCE_STEP for o in k.observations)
    assert k.observations[-1].change == pytest.approx(math.log(1.25), abs=0.06)
    assert all(ids[r] == [] for r in range(11, 15))


def test_an_action_that_leaves_the_place_is_linked_and_a_small_one_is_not():
    step = box(12_000.0, 12_040.0, math.log(1.3))  # from run 6 on, for good
    useless = Action(id=8, start_m=11_990.0, end_m=12_050.0, day=120.0)  # over it, but it stays
    small = Action(id=9, start_m=12_030.0, end_m=12_045.0, day=130.0)  # covers a quarter of it
    early = Action(id=10, start_m=11_900.0, end_m=12_100.0, day=20.0)  # before the place appeared
    index = _history(41, 14, lambda r: step if r >= 6 else 0.0 * step)
    known, events, _ = _advance(index, actions=[useless, small, early])
    assert len(known) == 1
    k = known[0]
    assert k.actions == [8] and k.active and k.listed
    assert {e.kind for evs in events.values() for e in evs} <= {"new", "tier"}
    assert k.confirmations == 8  # runs 6 … 13, through the actions


def test_a_tampings_own_effect_is_kept_as_its_record_and_never_alerted():
    tamping = Action(id=3, start_m=11_800.0, end_m=12_000.0, day=100.0)
    extent = box(tamping.start_m, tamping.end_m, math.log(0.8))
    index = _history(51, 14, lambda r: extent if r * EVERY > tamping.day else 0.0 * extent)
    known, events, _ = _advance(index, actions=[tamping])
    assert known and all(k.explained_by == 3 and not k.listed and k.direction == -1 for k in known)
    assert _kinds(events) == []


# --- alerts only on new places and tier changes ------------------------------------------------------


def test_no_alert_on_a_uniform_history_and_one_for_a_steady_place():
    index = _history(61, 24, lambda r: np.zeros(SEG.size))
    known, events, _ = _advance(index)
    assert _kinds(events) == [] and not [k for k in known if k.listed]
    steady = box(12_300.0, 12_330.0, 0.31)
    known, events, _ = _advance(_history(62, 24, lambda r: steady))
    assert _kinds(events) == [(6, "new", 1)]
    assert [k.id for k in known if k.listed] == [1] and known[0].confirmations == 19


def test_a_place_at_a_limit_does_not_ping_pong():
    at_limit = box(12_300.0, 12_330.0, 0.375)  # the intervention limit of b91
    index = _history(63, 30, lambda r: at_limit, natural=0.0)
    known, events, _ = _advance(index)
    assert len(known) == 1
    naive = np.array([o.tier for o in known[0].observations])
    flips = int(np.sum(naive[1:] != naive[:-1]))
    tiers = [e for evs in events.values() for e in evs if e.kind == "tier"]
    assert flips >= 6  # the run's own grading crosses the limit again and again …
    assert len(tiers) <= flips // 2  # … the place's tier falls only after two lower runs
    assert all(e.old_tier != e.new_tier for e in tiers)
    assert {e.kind for evs in events.values() for e in evs} <= {"new", "tier"}


# --- outlook -------------------------------------------------------------------------------------------


def _state(levels: Sequence[float], *, cls: str | None = "b91", tier: int = TIER_ALERT, every: float = EVERY,
           direction: int = 1) -> PlaceState:
    st = PlaceState(id=1, direction=direction, start_m=0.0, end_m=20.0, peak_m=10.0, cls=cls, tier=tier)
    for i, lv in enumerate(levels):
        st.observations.append(Observation(i, i * every, 0.0, 20.0, 10.0, 10.0, lv, math.nan, tier, abs(lv) / 0.25,
                                           1, 15))
    return st


def test_place_outlook_projects_to_the_next_limit_of_its_class_only():
    growing = _state([-0.26 - 0.01 * i for i in range(8)], direction=-1)  # a soft place getting softer
    out = place_outlook(growing, PARAMS.levels)
    assert out.tendency == "growing" and out.next_limit == 0.375
    rate = 0.01 / EVERY * 365.25
    assert out.trend.rate_per_year == pytest.approx(rate)
    assert out.projection.days == pytest.approx((0.375 - 0.33) / rate * 365.25)
    slab = place_outlook(_state([0.21 + 0.01 * i for i in range(8)], cls="slab"), PARAMS.levels)
    assert slab.next_limit == 0.3  # slab's intervention limit
    assert math.isnan(place_outlook(_state([0.3 + 0.01 * i for i in range(8)], cls=None), PARAMS.levels).next_limit)
    top = place_outlook(_state([0.7 + 0.01 * i for i in range(8)], tier=TIER_IMMEDIATE), PARAMS.levels)
    assert math.isnan(top.next_limit) and math.isnan(top.projection.days) and top.tendency == "growing"
    assert place_outlook(_state([0.3, 0.31]), PARAMS.levels).tendency == "new"


def test_place_outlook_window_reads_a_place_that_stopped_growing_as_stable():
    rng = np.random.default_rng(71)
    levels = np.r_[0.26 + 0.02 * np.arange(8), np.full(8, 0.40)] + rng.normal(0, 0.005, 16)
    st = _state(levels.tolist(), tier=TIER_INTERVENTION)
    assert place_outlook(st, PARAMS.levels).tendency == "growing"  # over its whole life
    recent = place_outlook(st, PARAMS.levels, window_days=7 * EVERY)
    assert recent.tendency == "stable" and recent.trend.n == 8 and math.isnan(recent.projection.days)


def test_the_time_to_limit_is_the_time_to_the_next_tier_as_the_tier_is_graded():
    """Issue 33: the real line's developing place (rough rails on pads, a stated 1-σ of 0.64) at −0.93, an
    intervention, read "≈ 0 d to immediate": its level lay beyond the immediate level limit (0.75) as it
    is, while its tier is graded on its 1-σ. The projection now reaches the severity at which the grading
    gives the next tier: just below it the tier stands, just beyond it rises."""
    from app.analysis.condition.run_places import DEFAULT_PLACE_PARAMS as P

    days = 14.0 * np.arange(11)
    hist = np.linspace(-0.20, -0.93, days.size)  # −0.73 / 140 d: growing at 1.9 ln units a year
    st = PlaceState(id=6, direction=-1, start_m=14_420.0, end_m=14_430.0, peak_m=14_425.0, cls="b91_pads",
                    baseline=-0.45, tier=TIER_INTERVENTION, listed=True)
    st.observations.append(Observation(22, days[-1], 14_420.0, 14_430.0, 14_425.0, 14_425.0, -0.93, -0.48,
                                       TIER_INTERVENTION, 4.8, 4, 3, level_sd=0.64, change_sd=0.64))
    trend = segment_trend(st, days, hist, now_day=days[-1])
    assert trend.level == pytest.approx(0.93) and trend.significant
    as_is = place_outlook(st, P.levels, trend=trend)
    assert as_is.projection.days == 0.0  # what the page showed
    out = place_outlook(st, P.levels, trend=trend, changes=P.changes)
    assert out.next_limit == 0.75 and out.projection.days > 30.0
    reach = graded_next_limit(st, P.levels, P.changes, trend.level)
    # here the change's route is the nearer one: 0.5 + 0.64 beyond its −0.48 (the level's needs 0.75 × 7.1)
    assert reach == pytest.approx(0.93 + 0.50 + 0.64 - 0.48)
    assert out.projection.days == pytest.approx((reach - 0.93) / trend.rate_per_year * 365.25)

    def tier_at(severity: float) -> int:
        grow = severity - 0.93
        return _graded(P, "b91_pads", -severity, -0.48 - grow, -1, TIER_INTERVENTION, 0.64, 0.64)

    assert tier_at(reach - 1e-3) == TIER_INTERVENTION and tier_at(reach + 1e-6) == TIER_IMMEDIATE
    # smooth rails (a stated 1-σ of 0.056, no change): the intervention limit of 0.375 graded is 0.466 as it
    # is; the alert tier comes at its limit as it is (a point size beyond a limit keeps at least the alert tier)
    def calm(tier: int) -> PlaceState:
        st = PlaceState(id=7, direction=1, start_m=0.0, end_m=10.0, peak_m=5.0, cls="b91", tier=tier)
        st.observations.append(Observation(1, 0.0, 0.0, 10.0, 5.0, 5.0, 0.2, math.nan, tier, 0.8, 4, 3,
                                           level_sd=0.056))
        return st

    lim = graded_next_limit(calm(TIER_ALERT), P.levels, P.changes, 0.3)
    assert lim == pytest.approx(0.375 * math.sqrt(1 + (0.056 / (0.25 / 3.3)) ** 2)) and 0.46 < lim < 0.47
    assert _graded(P, "b91", lim + 1e-6, 0.0, 1, TIER_ALERT, 0.056) == TIER_INTERVENTION
    assert _graded(P, "b91", lim - 1e-3, 0.0, 1, TIER_ALERT, 0.056) == TIER_ALERT
    # the alert tier at its limit as it is where the place's change is graded (a step's or a trend's); a place
    # first found by its level alone is graded by its run, its level graded throughout — its change as the
    # run read it (0.05 here) does not grade it
    stepped = calm(0)
    stepped.observations[-1] = replace(stepped.observations[-1], change=0.08, evidence=EVIDENCE_STEP)
    assert graded_next_limit(stepped, P.levels, P.changes, 0.2) == pytest.approx(0.2 + 0.10 - 0.08)  # the change's
    stepped.observations[-1] = replace(stepped.observations[-1], change=0.02)
    assert graded_next_limit(stepped, P.levels, P.changes, 0.2) == 0.25  # the level's
    by_level = calm(0)
    by_level.observations[-1] = replace(by_level.observations[-1], change=0.05, evidence=EVIDENCE_ANOMALY)
    assert graded_next_limit(by_level, P.levels, P.changes, 0.2) == pytest.approx(0.25 * lim / 0.375)
    assert _graded(P, "b91", 0.25 + 1e-6, 0.0, 1, 0, 0.056) == TIER_ALERT > _graded(P, "b91", 0.249, 0.0, 1, 0, 0.056)


# --- an action's effect: the extent against the track around it ---------------------------------------


def test_an_actions_effect_from_the_extent_against_its_surroundings_is_within_a_point():
    rng = np.random.default_rng(81)
    base = track(np.random.default_rng(82)) * 0.5
    days = np.arange(12) * EVERY
    tamping = Action(id=1, start_m=11_800.0, end_m=12_000.0, day=75.0)
    extent = box(tamping.start_m, tamping.end_m, math.log(0.8))
    # the runs after the work are also 6 % higher everywhere (another vehicle, a faster timetable)
    index = runs(rng, base, days.size, lambda r: (extent + 0.06) if days[r] > tamping.day else 0.0 * extent)
    level = index.mean(axis=0)
    rel = np.array([extent_level(SEG, level[:, r], tamping.start_m, tamping.end_m, segment_m=10.0)
                    for r in range(days.size)])
    absolute = np.array([extent_level(SEG, level[:, r], tamping.start_m, tamping.end_m, segment_m=10.0,
                                      relative=False) for r in range(days.size)])
    eff = action_effect(days, rel, tamping.day)
    assert 100 * math.expm1(eff.recovery) == pytest.approx(-20.0, abs=1.0)
    assert abs(100 * math.expm1(action_effect(days, absolute, tamping.day).recovery) + 20.0) > 4.0


def test_extent_level_reads_nan_without_data_and_checks_arguments():
    x = np.zeros(SEG.size)
    x[SEG < 1100] = np.nan
    assert math.isnan(extent_level(SEG, x, 10_500.0, 10_700.0, segment_m=10.0))
    assert extent_level(SEG, x + 0.1, 12_000.0, 12_100.0, segment_m=10.0, relative=False) == pytest.approx(0.1)
    with pytest.raises(ValueError, match="start_m, end_m"):
        extent_level(SEG, x, 12_000.0, 12_000.0, segment_m=10.0)
    with pytest.raises(ValueError, match="margin_m"):
        extent_level(SEG, x, 12_000.0, 12_100.0, segment_m=10.0, margin_m=-1.0)
    with pytest.raises(ValueError, match="seg, index"):
        extent_level(SEG, x[:5], 12_000.0, 12_100.0, segment_m=10.0)
    with pytest.raises(ValueError, match="min_segments"):
        extent_level(SEG, x, 12_000.0, 12_100.0, segment_m=10.0, min_segments=0)
    with pytest.raises(ValueError, match="min_inside"):
        extent_level(SEG, x, 12_000.0, 12_100.0, segment_m=10.0, min_inside=0)


def test_the_surroundings_are_the_mean_around_outside_the_widened_extent():
    x = np.zeros(SEG.size)
    centres = (SEG + 0.5) * 10.0
    x[(centres >= 11_950.0) & (centres < 12_150.0)] = 5.0  # the extent and its margins: never the surroundings
    x[np.abs(centres - 12_050.0) >= 500.0] = 9.0  # beyond around_m: neither
    x[(centres >= 11_700.0) & (centres < 11_800.0)] = 1.0  # inside the surroundings: 10 of the 80 segments
    level = surroundings_level(SEG, x, 12_000.0, 12_100.0, segment_m=10.0, around_m=500.0, margin_m=50.0)
    assert level == pytest.approx(10 * 1.0 / 80)
    assert extent_level(SEG, x, 12_000.0, 12_100.0, segment_m=10.0, around_m=500.0, margin_m=50.0) == \
        pytest.approx(5.0 - level)
    # one segment inside is enough where the caller says so (a trend's segment), the surroundings still need 3
    one = extent_level(SEG, x, 12_000.0, 12_010.0, segment_m=10.0, around_m=500.0, margin_m=50.0, min_inside=1)
    assert one == pytest.approx(5.0 - surroundings_level(SEG, x, 12_000.0, 12_010.0, segment_m=10.0,
                                                         around_m=500.0, margin_m=50.0))
    assert math.isnan(extent_level(SEG, x, 12_000.0, 12_010.0, segment_m=10.0))
    assert math.isnan(surroundings_level(SEG, x, 12_000.0, 12_100.0, segment_m=10.0, around_m=60.0,
                                         margin_m=50.0))



# --- a developing place read where it departs from its baseline --------------------------------------


def _demo_run(index: list[float], change: list[float], step: list[bool]):
    """A run's places over the segments km 13.64–13.70 (the numbers of the demo's runs 9 and 10 at its place
    developing at −1 ln unit a year, class b91 with pads): the trend found the middle, the step test only the
    taper's edge, whose rolling history had not absorbed the growth."""
    from app.analysis.condition.places import EVIDENCE_TREND, merge_places
    from app.analysis.condition.run_places import RunPlaces

    seg = np.arange(1364, 1370)
    idx, chg = np.array(index), np.array(change)
    hot = np.array([False, True, True, True, True, False])
    ev = np.where(hot, EVIDENCE_TREND, 0) | np.where(step, EVIDENCE_STEP, 0)
    value = np.where(step, chg, -1e-9)  # a trend segment's value: tiny (its change does not reach a limit)
    table = merge_places(seg, value, hot, segment_m=10.0, evidence=ev, wheels=np.where(hot, 3, 0))
    peak = 4  # the run's peak: the step segment (the only one with a tier)
    sd = np.full(seg.size, 0.08)
    cls = np.full(seg.size, "b91_pads", dtype=object)
    one = lambda a: np.array([a])  # noqa: E731
    return RunPlaces(places=table, peak_m=one((seg[peak] + 0.5) * 10.0), level=one(idx[peak]), change=one(chg[peak]),
                     change_z=one(-4.7), cls=cls[[peak]], level_tier=one(0), change_tier=one(1), tier=one(1),
                     severity=one(abs(chg[peak]) / 0.10), n_agreeing=one(2), rate_per_year=one(-0.6),
                     trend_z=one(-9.9), seg=seg, segment_m=10.0, seg_index=idx, seg_change=chg,
                     seg_change_z=np.zeros(seg.size), seg_class=cls, seg_evidence=ev.astype(np.int64),
                     level_sd=one(0.058), change_sd=one(0.034), severity_sd=one(0.34), seg_level_sd=sd)


def test_a_developing_place_is_read_at_its_worst_segment_against_its_baseline_and_keeps_its_tier():
    from app.analysis.condition.run_places import DEFAULT_PLACE_PARAMS

    # found by a step at km 13.66 (−0.32 against −0.10 before it): listed at the alert tier
    st = PlaceState(id=4, direction=-1, start_m=13_660.0, end_m=13_680.0, peak_m=13_665.0, cls="b91_pads",
                    baseline=-0.098, tier=TIER_ALERT, listed=True)
    for r, lv in enumerate((-0.321, -0.244, -0.329)):
        st.observations.append(Observation(6 + r, 14.0 * r, 13_660.0, 13_680.0, 13_670.0, 13_665.0, lv, lv + 0.098,
                                           TIER_ALERT, 2.0, EVIDENCE_STEP, 3))
    known, events = [st], []
    runs9_10 = (([-0.03, -0.20, -0.34, -0.24, -0.105, 0.11], [0.0, -0.09, -0.13, -0.13, -0.136, -0.02]),
                ([-0.03, -0.22, -0.37, -0.369, -0.149, 0.14], [0.0, -0.09, -0.13, -0.23, -0.162, 0.02]))
    for r, (idx, chg) in enumerate(runs9_10):
        found = _demo_run(idx, chg, [False, False, False, False, True, False])
        evs, ids, _ = advance_places(known, found, run_id=9 + r, day=42.0 + 14.0 * r, covered_m=(13_000.0, 14_000.0),
                                     params=LifecycleParams(), next_id=5, place_params=DEFAULT_PLACE_PARAMS)
        events += evs
        assert ids == [4]
    last = st.observations[-1]
    # read at its worst segment (km 13.66), not at the step's edge (−0.149, −0.05 from its baseline: watch)
    assert last.peak_m == 13_665.0 and last.level == pytest.approx(-0.37)
    assert last.change == pytest.approx(-0.37 + 0.098) and last.tier == TIER_ALERT
    assert last.severity == pytest.approx(0.272 / 0.10)
    # no tier-down alert for a place that grows
    assert st.tier == TIER_ALERT and events == []
    # its trend over the history of that segment (the demo's ten runs at km 13.66, two weeks apart) grows at
    # the planted rate and projects the intervention limit of its class
    hist = np.array([-0.041, -0.049, -0.082, -0.196, -0.253, -0.321, -0.235, -0.329, -0.342, -0.370])
    days = 14.0 * np.arange(hist.size)
    out = place_outlook(st, DEFAULT_PLACE_PARAMS.levels, trend=segment_trend(st, days, hist, now_day=days[-1]))
    assert out.tendency == "growing" and out.trend.low_per_year < 1.0 < out.trend.high_per_year
    assert out.next_limit == 0.45 and 0 < out.projection.days_early < out.projection.days < out.projection.days_late


# --- a known place held, based and graded on its reading's stated 1-σ (issue 33) ----------------------


def _quiet_run(index: list[float], sd: list[float], *, first: int = 1300):
    """A run that found no place over segments ``first …`` (class b91) with the given index and stated 1-σ."""
    from app.analysis.condition.places import merge_places
    from app.analysis.condition.run_places import RunPlaces

    seg = np.arange(first, first + len(index))
    idx = np.array(index, dtype=np.float64)
    cls = np.full(seg.size, "b91", dtype=object)
    table = merge_places(seg, idx, np.zeros(seg.size, bool), segment_m=10.0)
    e, ei = np.zeros(0), np.zeros(0, np.int64)
    return RunPlaces(places=table, peak_m=e, level=e, change=e, change_z=e, cls=np.zeros(0, object), level_tier=ei,
                     change_tier=ei, tier=ei, severity=e, n_agreeing=ei, rate_per_year=e, trend_z=e, seg=seg,
                     segment_m=10.0, seg_index=idx, seg_change=np.full(seg.size, np.nan),
                     seg_change_z=np.full(seg.size, np.nan), seg_class=cls, seg_evidence=np.zeros(seg.size, np.int64),
                     level_sd=e, change_sd=e, severity_sd=e, seg_level_sd=np.array(sd, dtype=np.float64))


def _listed(place_id: int, baseline: float, level: float, tier: int, *, direction: int = -1) -> PlaceState:
    st = PlaceState(id=place_id, direction=direction, start_m=13_010.0, end_m=13_020.0, peak_m=13_015.0, cls="b91",
                    baseline=baseline, tier=tier, listed=True)
    st.observations.append(Observation(1, 0.0, 13_010.0, 13_020.0, 13_015.0, 13_015.0, level, level - baseline, tier,
                                       abs(level - baseline) / 0.10, EVIDENCE_STEP, 3, 0.05, 0.05, 0.5))
    return st


def test_a_place_is_not_held_by_a_reading_within_its_stated_one_sigma_of_its_baseline():
    from app.analysis.condition.run_places import DEFAULT_PLACE_PARAMS

    # one run's −0.93 on rough rail, listed at once; the runs after it read −0.09 ± 0.39 there (−0.13 from its baseline): no departure
    st = _listed(7, 0.04, -0.89, TIER_IMMEDIATE)
    known = [st]
    for r in range(2):
        advance_places(known, _quiet_run([0.02, -0.09, 0.05], [0.39, 0.39, 0.39]), run_id=2 + r, day=15.0 * (r + 1),
                       covered_m=(12_000.0, 14_000.0), params=LifecycleParams(), next_id=8,
                       place_params=DEFAULT_PLACE_PARAMS)
    assert len(st.observations) == 1 and st.misses == 2 and not st.active
    # the same reading with a stated 1-σ of 0.02 departs beyond it: held, graded on the change's lower bound
    st2 = _listed(8, 0.04, -0.89, TIER_ALERT)
    advance_places([st2], _quiet_run([0.02, -0.09, 0.05], [0.02, 0.02, 0.02]), run_id=2, day=15.0,
                   covered_m=(12_000.0, 14_000.0), params=LifecycleParams(), next_id=9,
                   place_params=DEFAULT_PLACE_PARAMS)
    assert st2.active and st2.misses == 0 and st2.observations[-1].change == pytest.approx(-0.13)
    assert st2.observations[-1].change_sd == pytest.approx(0.02) and st2.observations[-1].tier == TIER_ALERT


def test_a_hard_place_receding_towards_the_typical_track_is_not_a_soft_place_of_its_change():
    from app.analysis.condition.run_places import DEFAULT_PLACE_PARAMS

    # a soft-going place whose baseline was +0.45 (a hard anomaly of class b91, alert 0.25), read at −0.06 ± 0.09:
    # its change of −0.51 is the hard place receding, not a soft place at the immediate tier; nor does it hold it
    st = _listed(5, 0.45, -0.40, TIER_IMMEDIATE)
    advance_places([st], _quiet_run([-0.03, -0.06, 0.01], [0.09, 0.09, 0.09]), run_id=2, day=15.0,
                   covered_m=(12_000.0, 14_000.0), params=LifecycleParams(), next_id=6,
                   place_params=DEFAULT_PLACE_PARAMS)
    assert len(st.observations) == 1 and st.misses == 1
    # read at −0.40 ± 0.09 it is a soft anomaly of its own (−0.31 on its lower bound): held
    st2 = _listed(6, 0.45, -0.40, TIER_IMMEDIATE)
    advance_places([st2], _quiet_run([-0.03, -0.40, 0.01], [0.09, 0.09, 0.09]), run_id=2, day=15.0,
                   covered_m=(12_000.0, 14_000.0), params=LifecycleParams(), next_id=7,
                   place_params=DEFAULT_PLACE_PARAMS)
    assert len(st2.observations) == 2 and st2.observations[-1].level == pytest.approx(-0.40)


def test_a_place_takes_its_baseline_from_a_step_on_its_own_ground_only():
    from app.analysis.condition.places import EVIDENCE_ANOMALY, merge_places
    from app.analysis.condition.run_places import DEFAULT_PLACE_PARAMS, RunPlaces

    # a lasting hard anomaly (+0.57) at km 13.000–13.010, first found without a step (no baseline); a run finds a
    # step +0.28 at the segment beside it (km 12.990, −0.22): the run's place is matched to it, but that step is
    # not the place's own ground before it changed
    st = PlaceState(id=1, direction=1, start_m=13_000.0, end_m=13_010.0, peak_m=13_005.0, cls="b91", tier=TIER_ALERT,
                    listed=True)
    st.observations.append(Observation(1, 0.0, 13_000.0, 13_010.0, 13_005.0, 13_005.0, 0.57, float("nan"),
                                       TIER_ALERT, 2.3, EVIDENCE_ANOMALY, 3, 0.2))
    seg = np.arange(1298, 1301)
    idx, chg = np.array([-0.22, 0.05, 0.02]), np.array([0.28, 0.0, 0.0])
    hot = np.array([True, False, False])
    ev = np.where(hot, EVIDENCE_STEP, 0).astype(np.int64)
    table = merge_places(seg, chg, hot, segment_m=10.0, evidence=ev, wheels=np.where(hot, 3, 0))
    cls = np.full(seg.size, "b91", dtype=object)
    one = lambda a: np.array([a])  # noqa: E731
    found = RunPlaces(places=table, peak_m=one(12_985.0), level=one(-0.22), change=one(0.28), change_z=one(5.0),
                      cls=cls[[0]], level_tier=one(0), change_tier=one(1), tier=one(1), severity=one(2.8),
                      n_agreeing=one(2), rate_per_year=one(np.nan), trend_z=one(np.nan), seg=seg, segment_m=10.0,
                      seg_index=idx, seg_change=chg, seg_change_z=np.zeros(seg.size), seg_class=cls,
                      seg_evidence=ev, level_sd=one(0.37), change_sd=one(0.05), severity_sd=one(0.5),
                      seg_level_sd=np.full(seg.size, 0.2))
    _, ids, _ = advance_places([st], found, run_id=2, day=15.0, covered_m=(12_000.0, 14_000.0),
                               params=LifecycleParams(), next_id=2, place_params=DEFAULT_PLACE_PARAMS)
    assert ids == [1] and st.baseline is None


def test_pieces_of_one_change_are_one_place_read_over_their_merged_extent():
    from app.analysis.condition.run_places import DEFAULT_PLACE_PARAMS

    # a 30 m soft spot at km 13.130–13.160 known as two places, 10 m apart (each held on its own 10 m reading)
    a = PlaceState(id=19, direction=-1, start_m=13_130.0, end_m=13_140.0, peak_m=13_135.0, cls="b91", baseline=0.0,
                   tier=TIER_INTERVENTION, listed=True)
    b = PlaceState(id=20, direction=-1, start_m=13_150.0, end_m=13_160.0, peak_m=13_155.0, cls="b91", baseline=0.0,
                   tier=TIER_ALERT, listed=True)
    for st in (a, b):
        st.observations.append(Observation(1, 0.0, st.start_m, st.end_m, st.peak_m, st.peak_m, -0.45, -0.45, st.tier,
                                           4.5, EVIDENCE_STEP, 3, 0.1, 0.1, 1.0))
    a.observations[0] = Observation(1, -15.0, *[getattr(a.observations[0], f) for f in
                                                ("start_m", "end_m", "centre_m", "peak_m", "level", "change", "tier",
                                                 "severity", "evidence", "wheels", "level_sd", "change_sd",
                                                 "severity_sd")])
    known = [a, b]
    all_events = []
    for r in range(2):
        # the soft spot over segments 1313–1315 (−0.45, −0.30, −0.50), typical track beside it
        evs, _, _ = advance_places(known, _quiet_run([0.0, 0.02, -0.45, -0.30, -0.50, 0.01], [0.1] * 6, first=1311),
                                   run_id=2 + r, day=15.0 * (r + 1), covered_m=(12_000.0, 14_000.0),
                                   params=LifecycleParams(), next_id=21, place_params=DEFAULT_PLACE_PARAMS)
        all_events.append(evs)
        listed = [k for k in known if k.active and k.listed]
        # one place, the older one, over both pieces, at the higher tier
        assert [(k.id, k.start_m, k.end_m, k.tier) for k in listed] == [(19, 13_130.0, 13_160.0, TIER_INTERVENTION)]
    # from the next run on read over the merged extent: at its worst segment (km 13.155)
    assert a.observations[-1].level == pytest.approx(-0.50) and a.observations[-1].peak_m == 13_155.0
    # the piece (held on its own by the first run, before the merge) neither comes back as a place of its own nor
    # raises an alert after it
    assert not b.active and all_events[1] == [] and len(b.observations) == 2
