"""A place is read against passes like the run's own (issue 33): on rough rails a 10 m segment's index is the
rails' response as much as the support's, and that response changes with the speed and the vehicle. A run's
step and trend tests compare it with its history's matched passes (same vehicle, matched speed: the flags'
rule, :func:`app.analysis.condition.change.matched_passes`), and a known place's change is read against its
baseline at the run's pass (:class:`app.analysis.condition.lifecycle.PassHistory`)."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.condition.change import ChangeParams, matched_passes
from app.analysis.condition.lifecycle import LifecycleParams, PassHistory, advance_places
from app.analysis.condition.places import EVIDENCE_STEP
from app.analysis.condition.run_places import find_places
from app.analysis.condition.tiers import TIER_IMMEDIATE
from tests.condition.places_support import PARAMS, SEG, W, box, runs, track

CLS = np.full(SEG.size, "b91", dtype=object)
SLOW, FAST = 26.0, 40.0  # m/s, the two cruise groups
#: the rails' response at one 10 m segment (km 11.5): +0.45 ln units at 26 m/s, −0.45 at 40 m/s, run after run
RAIL = box(11_500.0, 11_510.0, 1.0) * 0.45


def _line(n: int, *, extra=None, seed: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(W, S, n) index, speed (m/s) and (n,) days of runs alternating two and two between the speed groups."""
    speeds = np.array([SLOW if (r // 2) % 2 else FAST for r in range(n)])
    rail = [RAIL if v == SLOW else -RAIL for v in speeds]
    x = runs(np.random.default_rng(seed), track(np.random.default_rng(seed + 1)) * 0.3, n,
             lambda r: rail[r] + (extra(r) if extra is not None else 0.0))
    return x, np.broadcast_to(speeds[None, None, :], x.shape).copy(), np.arange(n) * 15.0


def _places(x, v, days, r, **kw):
    return find_places(SEG, x[:, :, r], x[:, :, :r], days[:r], days[r], CLS, segment_m=10.0, params=PARAMS,
                       speed=v[:, :, r], history_speed=v[:, :, :r], **kw)


def _at(rp, km_m: float) -> list[int]:
    return [i for i in range(len(rp.places)) if rp.places.start_m[i] - 10 <= km_m <= rp.places.end_m[i] + 10]


def test_a_change_on_a_rough_rail_is_found_against_the_passes_at_the_runs_speed():
    # the support under the rail's response at km 11.5 changes by −0.36 in the newest run, at 40 m/s
    x, v, days = _line(13, extra=lambda k: box(11_500.0, 11_510.0, -0.36) if k == 12 else 0.0 * RAIL)
    assert v[0, 0, 12] == FAST
    # against every earlier run (+0.45 at 26 m/s, −0.45 at 40 m/s) the rails' response hides it
    blind = find_places(SEG, x[:, :, 12], x[:, :, :12], days[:12], days[12], CLS, segment_m=10.0, params=PARAMS)
    assert not any(blind.places.evidence[i] & EVIDENCE_STEP for i in _at(blind, 11_505.0))
    # against the passes at its speed it is a step of its size, and the only place of the run
    rp = _places(x, v, days, 12)
    hit = _at(rp, 11_505.0)
    assert len(rp.places) == 1 and hit and rp.places.evidence[hit[0]] & EVIDENCE_STEP
    assert rp.change[hit[0]] == pytest.approx(-0.36, abs=0.06)
    # the run before it, at 40 m/s too, has no step there (the rail's −0.45 is a level anomaly of that pass, as it
    # is in every 40 m/s run): the rail's response is no change at its own speed
    quiet = _places(x, v, days, 9)
    assert v[0, 0, 9] == FAST and not any(quiet.places.evidence[i] & EVIDENCE_STEP for i in _at(quiet, 11_505.0))
    assert all(quiet.places.evidence[i] & EVIDENCE_STEP == 0 for i in range(len(quiet.places)))


def test_another_vehicles_passes_are_not_a_baseline_for_a_vehicle_first_seen():
    # the same change read by a second vehicle on its first pass at 40 m/s: with none of its own passes there (fewer
    # than two), nothing is tested, so no step; the first vehicle's run finds it
    x, v, days = _line(13, extra=lambda k: box(11_500.0, 11_510.0, -0.36) if k == 12 else 0.0 * RAIL)
    veh = np.array(["V1"] * 12, dtype=object)
    rp = _places(x, v, days, 12, vehicle="V2", history_vehicle=veh)
    assert not any(rp.places.evidence[i] & EVIDENCE_STEP for i in range(len(rp.places)))
    rp1 = _places(x, v, days, 12, vehicle="V1", history_vehicle=veh)
    assert [bool(rp1.places.evidence[i] & EVIDENCE_STEP) for i in _at(rp1, 11_505.0)] == [True]


def test_matched_passes_keep_the_same_vehicle_at_a_matched_speed_only():
    h = np.array([[0.1, 0.2, 0.3, 0.4, 0.5, 0.6]])
    hv = np.array([[40.0, 26.0, 40.0, 40.0, 26.0, 40.0]])
    veh = np.array(["A", "A", "B", "A", "A", "A"], dtype=object)
    params = ChangeParams(min_history=2)
    m = matched_passes(h, hv, np.array([40.0]), params, history_vehicle=veh, vehicle="A")
    np.testing.assert_allclose(m.history[0], [0.1, np.nan, np.nan, 0.4, np.nan, 0.6])
    assert m.testable.all()
    # no vehicles: every pass at a matched speed
    m = matched_passes(h, hv, np.array([40.0]), params)
    np.testing.assert_allclose(m.history[0], [0.1, np.nan, 0.3, 0.4, np.nan, 0.6])
    with pytest.raises(ValueError, match="history_speed"):
        find_places(SEG, np.zeros((W, SEG.size)), np.zeros((W, SEG.size, 2)), np.zeros(2), 30.0, CLS, segment_m=10.0,
                    params=PARAMS, speed=np.ones((W, SEG.size)), history_speed=np.ones((W, SEG.size, 3)))
    with pytest.raises(ValueError, match="history_vehicle"):
        find_places(SEG, np.zeros((W, SEG.size)), np.zeros((W, SEG.size, 2)), np.zeros(2), 30.0, CLS, segment_m=10.0,
                    params=PARAMS, history_vehicle=np.array(["A"], dtype=object))


def _quiet(index: list[float], sd: float, first: int = 1300):
    from tests.condition.test_lifecycle import _quiet_run

    return _quiet_run(index, [sd] * len(index), first=first)


def _soft_place(baseline: float, level: float):
    from tests.condition.test_lifecycle import _listed

    return _listed(4, baseline, level, TIER_IMMEDIATE)


def test_a_place_is_read_against_its_baseline_at_the_runs_pass():
    from app.analysis.condition.run_places import DEFAULT_PLACE_PARAMS

    # a place found by a step at 26 m/s (baseline +0.32 there, level −0.07); the rail reads −0.85 at 40 m/s, where
    # its passes before it was found read −0.80: the 40 m/s run's −0.83 is −0.03 from its baseline, not −1.15
    days = np.array([-60.0, -45.0, -30.0, -15.0])
    hist = np.full((3, 4), np.nan)
    hist[1] = [-0.80, -0.79, np.nan, -0.81]  # segment 1301 (the place's), the 40 m/s passes
    st = _soft_place(0.32, -0.07)
    known = [st]
    advance_places(known, _quiet([0.02, -0.83, 0.05], 0.05), run_id=2, day=15.0, covered_m=(12_000.0, 14_000.0),
                   params=LifecycleParams(), next_id=8, place_params=DEFAULT_PLACE_PARAMS,
                   passes=PassHistory(hist, days))
    assert len(st.observations) == 1 and st.misses == 1  # not held: back at its baseline at this pass
    # read the old way, against its one baseline, the same run held it at −1.15, "immediate"
    st_old = _soft_place(0.32, -0.07)
    advance_places([st_old], _quiet([0.02, -0.83, 0.05], 0.05), run_id=2, day=15.0, covered_m=(12_000.0, 14_000.0),
                   params=LifecycleParams(), next_id=8, place_params=DEFAULT_PLACE_PARAMS)
    assert st_old.observations[-1].change == pytest.approx(-1.15) and st_old.observations[-1].tier == TIER_IMMEDIATE
    # a real departure at this pass holds it, against that pass's baseline (the median of its passes before)
    st2 = _soft_place(0.32, -0.07)
    advance_places([st2], _quiet([0.02, -1.20, 0.05], 0.05), run_id=2, day=15.0, covered_m=(12_000.0, 14_000.0),
                   params=LifecycleParams(), next_id=8, place_params=DEFAULT_PLACE_PARAMS,
                   passes=PassHistory(hist, days))
    assert st2.active and st2.observations[-1].change == pytest.approx(-0.40)
    # no pass like the run's in its history: its change cannot be read there, and it does not hold the place
    st3 = _soft_place(0.32, -0.07)
    advance_places([st3], _quiet([0.02, -1.20, 0.05], 0.05), run_id=2, day=15.0, covered_m=(12_000.0, 14_000.0),
                   params=LifecycleParams(), next_id=8, place_params=DEFAULT_PLACE_PARAMS,
                   passes=PassHistory(np.full((3, 4), np.nan), days))
    assert len(st3.observations) == 1 and st3.misses == 1


def test_a_pass_history_takes_the_passes_before_the_place_else_its_first_since():
    ph = PassHistory(np.array([[0.1, 0.3, np.nan, -0.4, -0.5]]), np.array([0.0, 15.0, 30.0, 45.0, 60.0]))
    assert ph.baseline(0, 40.0) == pytest.approx(0.2)
    assert ph.baseline(0, 10.0) == pytest.approx(0.1)
    assert ph.baseline(0, 0.0) == pytest.approx(0.1)  # none before: its first pass since
    assert PassHistory(np.full((1, 2), np.nan), np.zeros(2)).baseline(0, 5.0) is None
    with pytest.raises(ValueError, match="values, days"):
        PassHistory(np.zeros((2, 3)), np.zeros(2))
    with pytest.raises(ValueError, match="passes"):
        advance_places([], _quiet([0.0, 0.0], 0.05), run_id=1, day=0.0, covered_m=(0.0, 1.0),
                       params=LifecycleParams(), next_id=1, passes=PassHistory(np.zeros((3, 1)), np.zeros(1)))


def test_a_level_is_graded_in_units_of_the_healthy_scatter_at_its_pass():
    from app.analysis.condition.run_places import HEALTHY_ALERT_Z, graded_level

    sigma0 = 0.25 / HEALTHY_ALERT_Z
    # without a stated 1-σ, as it is; with one, |level| / √(1 + (sd / σ0)²)
    np.testing.assert_allclose(graded_level([0.5, -0.5, np.nan], [np.nan, 0.0, 0.1], 0.25), [0.5, 0.5, np.nan])
    assert float(graded_level(0.9, 0.3, 0.25)) == pytest.approx(0.9 / np.sqrt(1 + (0.3 / sigma0) ** 2))
    # smooth rails (1-σ 0.056): the alert limit needs about the level less its 1-σ, as the lower bound did ...
    need = 0.25 * np.sqrt(1 + (0.056 / sigma0) ** 2)
    assert need == pytest.approx(0.25 + 0.056, abs=0.01)
    # ... rough rails (1-σ 0.3): 3.3 σ of the healthy scatter at the pass, not 1.8 σ
    need_rough = 0.25 * np.sqrt(1 + (0.3 / sigma0) ** 2)
    assert need_rough / np.hypot(sigma0, 0.3) == pytest.approx(HEALTHY_ALERT_Z)
    assert (0.25 + 0.3) / np.hypot(sigma0, 0.3) < 1.9
    # a class without limits (inf) grades as it is
    assert float(graded_level(0.4, 0.3, np.inf)) == pytest.approx(0.4)


def test_a_rough_rails_level_within_its_scatter_is_no_place_and_a_change_there_is():
    from app.analysis.condition.run_places import DEFAULT_PLACE_PARAMS

    # a rough line: every pass's 10 m level uncertain by 0.3 (the rails' response); a segment reads +0.70 at every
    # pass (roughness at the sleeper spacing): within 3.3 σ of the healthy scatter there, no place; a −0.36 change of
    # the support beside it in the newest run, against passes within ±0.02: a step
    rng = np.random.default_rng(5)
    n = 9
    base = track(np.random.default_rng(6)) * 0.3 + box(11_500.0, 11_510.0, 0.70)
    x = runs(rng, base, n, lambda k: box(12_000.0, 12_020.0, -0.36) if k == n - 1 else 0.0 * base)
    sd = np.full(x.shape, 0.3)
    cls = np.full(SEG.size, "b91", dtype=object)
    rp = find_places(SEG, x[:, :, -1], x[:, :, :-1], np.arange(n - 1.0), n - 1.0, cls, segment_m=10.0,
                     params=DEFAULT_PLACE_PARAMS, index_sd=sd[:, :, -1], history_sd=sd[:, :, :-1])
    assert not _at(rp, 11_505.0)
    hit = _at(rp, 12_010.0)
    assert len(rp.places) == 1 and hit and rp.places.evidence[hit[0]] & EVIDENCE_STEP
