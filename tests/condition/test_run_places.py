"""A run's places from the speed-conditioned index (anomaly against the class, step against the own
history) and their lifecycle over runs (listing, tier changes, misses, alerts), on synthetic truth."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.condition.lifecycle import LifecycleParams, advance_places, severity_trend
from app.analysis.condition.places import EVIDENCE_ANOMALY, EVIDENCE_STEP, EVIDENCE_TREND
from app.analysis.condition.run_places import PlaceParams, find_places, segment_index
from app.analysis.stiffness.reference_curve import ReferenceCurve
from tests.condition.places_support import NOISE, PARAMS, SEG, W
from tests.condition.places_support import box as _box
from tests.condition.places_support import runs as _runs
from tests.condition.places_support import track as _track


def test_a_new_20m_change_is_one_step_place_at_its_km():
    rng = np.random.default_rng(1)
    track = _track(rng)
    hist = _runs(rng, track, 8)
    new = _runs(rng, track, 1, lambda r: _box(11_503.0, 11_523.0, np.log(0.8)))[:, :, 0]
    cls = np.full(SEG.size, "b91", dtype=object)
    rp = find_places(SEG, new, hist, np.arange(8) * 14.0, 8 * 14.0, cls, segment_m=10.0, params=PARAMS)
    assert len(rp) == 1
    p = rp.places
    assert p.direction[0] == -1 and p.evidence[0] & EVIDENCE_STEP
    assert abs(p.centre_m[0] - 11_513.0) < 5.0
    assert rp.change_tier[0] == 1 and rp.tier[0] == 1  # 0.10 ≤ |ln 0.8| = 0.223 < 0.30
    assert rp.n_agreeing[0] == 4 and p.wheels[0] == 0b1111
    assert rp.change[0] == pytest.approx(np.log(0.8), abs=0.06)


def test_uniform_history_gives_no_place_and_no_history_no_step():
    rng = np.random.default_rng(2)
    track = _track(rng)
    hist = _runs(rng, track, 10)
    new = _runs(rng, track, 1)[:, :, 0]
    cls = np.full(SEG.size, "b91", dtype=object)
    assert len(find_places(SEG, new, hist, np.arange(10.0), 10.0, cls, segment_m=10.0, params=PARAMS)) == 0
    # a step-sized change with too little history is not a step (level below the limit)
    new2 = new + _box(11_500.0, 11_520.0, 0.2)[None, :]
    rp = find_places(SEG, new2, hist[:, :, :3], np.arange(3.0), 3.0, cls, segment_m=10.0, params=PARAMS)
    assert all(not (e & EVIDENCE_STEP) for e in rp.places.evidence)


def test_a_lasting_anomaly_is_graded_by_the_limits_of_its_class():
    rng = np.random.default_rng(3)
    track = _track(rng) * 0.5 + _box(11_000.0, 11_030.0, 0.33)  # lasting, in history too
    hist = _runs(rng, track, 8)
    new = _runs(rng, track, 1)[:, :, 0]
    cls = np.where(SEG < 1150, "slab", "b91").astype(object)
    rp = find_places(SEG, new, hist, np.arange(8.0), 8.0, cls, segment_m=10.0, params=PARAMS)
    assert len(rp) == 1 and rp.places.evidence[0] == EVIDENCE_ANOMALY
    assert rp.cls[0] == "slab" and rp.level_tier[0] == 2  # 0.33 ≥ slab's 0.3
    cls_b = np.full(SEG.size, "b91", dtype=object)
    rp_b = find_places(SEG, new, hist, np.arange(8.0), 8.0, cls_b, segment_m=10.0, params=PARAMS)
    assert rp_b.level_tier[0] == 1  # the default limits: 0.25 ≤ 0.33 < 0.375
    assert rp_b.severity[0] == pytest.approx(abs(rp_b.level[0]) / 0.25)
    none = np.full(SEG.size, None, dtype=object)  # no class (a superstructure change): no level test
    assert len(find_places(SEG, new, hist, np.arange(8.0), 8.0, none, segment_m=10.0, params=PARAMS)) == 0


def test_find_places_checks_arguments():
    x = np.zeros((W, SEG.size))
    h = np.zeros((W, SEG.size, 2))
    cls = np.full(SEG.size, "b91", dtype=object)
    with pytest.raises(ValueError, match="history"):
        find_places(SEG, x, np.zeros((W, 3, 2)), np.arange(2.0), 2.0, cls, segment_m=10.0, params=PARAMS)
    with pytest.raises(ValueError, match="history_days"):
        find_places(SEG, x, h, np.arange(3.0), 2.0, cls, segment_m=10.0, params=PARAMS)
    with pytest.raises(ValueError, match="classes"):
        find_places(SEG, x, h, np.arange(2.0), 2.0, cls[:5], segment_m=10.0, params=PARAMS)
    with pytest.raises(TypeError, match="params"):
        find_places(SEG, x, h, np.arange(2.0), 2.0, cls, segment_m=10.0, params=None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="min_history"):
        PlaceParams(PARAMS.levels, PARAMS.changes, min_history=1)


def test_segment_index_uses_the_curve_of_each_class():
    nodes = np.log(np.array([10.0, 20.0, 40.0]))
    curve = ReferenceCurve("slab", nodes, np.array([0.0, 1.0, 2.0]), np.zeros(3), np.zeros(3), np.zeros(3),
                           np.full(3, 100), np.full(3, 5), 0.1, "within", 10, 10, 5, 0.05)
    la = np.array([[1.0, 1.0, 1.0]])
    v = np.array([[20.0, 20.0, 20.0]])
    got = segment_index(la, v, np.array(["slab", "b91", None], dtype=object), {"slab": curve})
    assert got[0, 0] == pytest.approx(0.0) and np.isnan(got[0, 1]) and np.isnan(got[0, 2])


# --- lifecycle ---------------------------------------------------------------------------------


def _found(rng, track_extra_by_run, n_hist=8):
    """find_places of consecutive runs on one line with the given extra per run (in its history too:
    the places are graded by their level, not by a step)."""
    track = _track(np.random.default_rng(10)) * 0.5
    cls = np.full(SEG.size, "b91", dtype=object)
    for r, extra in enumerate(track_extra_by_run):
        hist = _runs(rng, track + extra, n_hist)
        new = _runs(rng, track + extra, 1)[:, :, 0]
        yield r, find_places(SEG, new, hist, np.arange(n_hist, dtype=float) - n_hist, 0.0, cls, segment_m=10.0,
                             params=PARAMS)


def test_lifecycle_lists_after_two_runs_and_alerts_only_on_new_tier_and_back():
    rng = np.random.default_rng(4)
    spot = _box(12_000.0, 12_030.0, 1.0)
    # runs: nothing, 0.28 (alert tier, seen once: candidate), 0.28 (listed: "new"), 0.30, 0.45 (tier up),
    # 0.30, 0.30 (tier down after two lower runs), gone, gone (inactive), 0.30 (back)
    sizes = [0.0, 0.28, 0.28, 0.30, 0.45, 0.30, 0.30, 0.0, 0.0, 0.30]
    known, next_id, log = [], 1, []
    params = LifecycleParams()
    for r, rp in _found(rng, [s * spot for s in sizes]):
        events, ids, next_id = advance_places(known, rp, run_id=r, day=14.0 * r, covered_m=(10_000.0, 13_000.0),
                                              params=params, next_id=next_id)
        log.append([(e.kind, e.old_tier, e.new_tier) for e in events])
    assert log == [[], [], [("new", 0, 1)], [], [("tier", 1, 2)], [], [("tier", 2, 1)], [], [], [("back", 1, 1)]]
    assert len(known) == 1 and known[0].id == 1 and known[0].confirmations == 7
    assert known[0].first_seen_day == 14.0 and known[0].last_confirmed_day == 126.0


def test_a_single_run_candidate_is_forgotten_and_an_intervention_place_is_listed_at_once():
    rng = np.random.default_rng(5)
    spot = _box(12_000.0, 12_030.0, 1.0)
    other = _box(11_000.0, 11_020.0, 1.0)
    sizes = [(0.28, 0.0), (0.0, 0.45), (0.0, 0.45), (0.0, 0.0)]
    known, next_id, log = [], 1, []
    for r, rp in _found(rng, [a * spot + b * other for a, b in sizes]):
        events, ids, next_id = advance_places(known, rp, run_id=r, day=float(r), covered_m=(10_000.0, 13_000.0),
                                              params=LifecycleParams(), next_id=next_id)
        log.append([(e.place_id, e.kind) for e in events])
    assert log == [[], [(2, "new")], [], []]
    assert [k.id for k in known] == [2]  # the candidate 1 missed twice: forgotten
    assert known[0].misses == 1 and known[0].active


def test_a_run_that_does_not_cover_a_place_does_not_miss_it_and_trend_of_a_growing_place():
    rng = np.random.default_rng(6)
    spot = _box(12_000.0, 12_040.0, 1.0)
    sizes = [0.30, 0.33, 0.36, 0.39, 0.42, 0.45]
    known, next_id = [], 1
    for r, rp in _found(rng, [s * spot for s in sizes]):
        _, _, next_id = advance_places(known, rp, run_id=r, day=14.0 * r, covered_m=(10_000.0, 13_000.0),
                                       params=LifecycleParams(), next_id=next_id)
    tr = severity_trend(known[0])
    assert tr.significant and tr.rate_per_year == pytest.approx(0.03 / 14 * 365.25, rel=0.25)
    from app.analysis.condition.lifecycle import place_outlook

    out = place_outlook(known[0], PARAMS.levels)
    assert out.tendency == "growing" and out.next_limit == 0.625  # intervention now (0.45): next immediate
    # the last level ~0.45 grows ~0.78 a year: ~0.175 / 0.78 years to 0.625
    assert out.projection.days == pytest.approx((0.625 - tr.level) / tr.rate_per_year * 365.25)
    empty = next(_found(rng, [0.0 * spot]))[1]
    advance_places(known, empty, run_id=99, day=100.0, covered_m=(10_000.0, 11_500.0), params=LifecycleParams(),
                   next_id=next_id)
    assert known[0].misses == 0
    with pytest.raises(ValueError, match="covered_m"):
        advance_places(known, empty, run_id=100, day=101.0, covered_m=(2.0, 1.0), params=LifecycleParams(),
                       next_id=next_id)


def test_segment_curves_recover_the_speed_law_of_segment_rows():
    from app.analysis.condition.segment_curves import fit_segment_curves, segment_samples

    rng = np.random.default_rng(7)
    seg = np.arange(400)
    location = rng.normal(0, 0.08, (2, seg.size))  # per rail
    rows = []
    for run in range(8):
        v = 30.0 * (1 + 0.1 * rng.uniform(-1, 1)) * (1 + 0.3 * np.clip((seg - 350) / 50, 0, 1))
        for w in ("11", "12", "41", "42"):
            la = 1.5 * np.log(v / 30.0) + location[int(w[1]) - 1] + rng.normal(0, 0.03, seg.size)
            rows.append((seg, la, v, np.full(seg.size, run), np.full(seg.size, w), np.full(seg.size, "slab", object)))
    cols = [np.concatenate([r[j] for r in rows]) for j in range(6)]
    curve = fit_segment_curves(*cols)["slab"]
    g, _ = curve.evaluate(np.array([30.0, 33.0]))
    assert g[1] - g[0] == pytest.approx(1.5 * np.log(1.1), abs=0.03)  # the within-location slope
    s = segment_samples(*cols)
    assert len(s) == cols[0].size and len(np.unique(s.location)) == 2 * seg.size
    cls = cols[5].copy()
    cls[:10] = None
    assert len(segment_samples(cols[0], cols[1], cols[2], cols[3], cols[4], cls)) == cols[0].size - 10
    with pytest.raises(ValueError, match="equal length"):
        segment_samples(cols[0], cols[1][:5], cols[2], cols[3], cols[4], cols[5])


def test_a_growing_place_below_the_limits_is_found_by_its_trend():
    from app.analysis.condition.places import EVIDENCE_TREND

    rng = np.random.default_rng(8)
    track = _track(rng) * 0.3
    spot = _box(12_000.0, 12_040.0, 1.0)
    days = np.arange(9) * 14.0  # 8 earlier runs and the new one, growing 0.6 per year
    runs = _runs(rng, track, 9, lambda r: spot * 0.6 * days[r] / 365.25)
    cls = np.full(SEG.size, "b91", dtype=object)
    rp = find_places(SEG, runs[:, :, -1], runs[:, :, :-1], days[:-1], days[-1], cls, segment_m=10.0, params=PARAMS)
    assert len(rp) == 1
    assert rp.places.evidence[0] & EVIDENCE_TREND and rp.tier[0] == 0  # level 0.18 < 0.25: watch
    assert rp.rate_per_year[0] == pytest.approx(0.6, rel=0.2)
    assert 12_000.0 <= rp.places.centre_m[0] <= 12_040.0
    # a place recovering towards typical track (negative rate on a positive level) is not a trend place
    back = _runs(rng, track, 9, lambda r: spot * (0.2 - 0.6 * days[r] / 365.25))
    rp2 = find_places(SEG, back[:, :, -1], back[:, :, :-1], days[:-1], days[-1], cls, segment_m=10.0, params=PARAMS)
    assert all(not (e & EVIDENCE_TREND) or d < 0 for e, d in zip(rp2.places.evidence, rp2.places.direction,
                                                                   strict=True))


def test_a_lasting_step_is_held_against_its_baseline_and_a_repair_drops_it():
    rng = np.random.default_rng(9)
    track = _track(np.random.default_rng(11)) * 0.5
    spot = _box(12_000.0, 12_020.0, np.log(1.2))  # +20 % from run 6 on, repaired (gone) from run 14
    cls = np.full(SEG.size, "b91", dtype=object)
    all_runs = _runs(rng, track, 18, lambda r: spot if 6 <= r < 14 else 0.0 * spot)
    days = np.arange(18) * 7.0
    known, next_id, active = [], 1, []
    for r in range(5, 18):
        rp = find_places(SEG, all_runs[:, :, r], all_runs[:, :, :r], days[:r], days[r], cls, segment_m=10.0,
                         params=PARAMS)
        advance_places(known, rp, run_id=r, day=days[r], covered_m=(10_000.0, 13_000.0), params=LifecycleParams(),
                       next_id=next_id, place_params=PARAMS)
        next_id = max([k.id for k in known], default=0) + 1
        spot_places = [k for k in known if k.start_m < 12_030 and k.end_m > 11_990]
        active.append(bool(spot_places) and spot_places[0].active and spot_places[0].listed)
        if spot_places and r == 13:
            k = spot_places[0]
            assert k.baseline is not None and k.observations[-1].change == pytest.approx(np.log(1.2), abs=0.07)
            assert k.confirmations == 8  # runs 6 … 13: found by the step, then held against its baseline
    # runs 5 … 17: nothing; found on 6 (alert tier: not listed yet); listed from 7 and held to 13; back at
    # its baseline from 14: missed by 14 (still active) and 15 (inactive from then on)
    assert active == [False, False] + [True] * 7 + [True, False, False, False]


def test_a_tamping_repairs_the_place_it_covers_and_its_own_effect_is_not_a_new_place():
    from app.analysis.condition.lifecycle import Action

    rng = np.random.default_rng(12)
    track = _track(np.random.default_rng(13)) * 0.5
    cls = np.full(SEG.size, "b91", dtype=object)
    days = np.arange(16) * 14.0
    tamping = Action(id=77, start_m=11_900.0, end_m=12_100.0, day=150.0)
    spot = _box(12_000.0, 12_040.0, 1.0)
    extent = _box(tamping.start_m, tamping.end_m, 1.0)

    def extra(r: int) -> np.ndarray:
        if days[r] < tamping.day:  # a hard place growing 1.2 a year from 0.2
            return spot * (0.2 + 1.2 * days[r] / 365.25)
        return extent * np.log(0.8)  # repaired, the whole extent 20 % lower

    runs = _runs(rng, track, days.size, extra)
    known, next_id, log = [], 1, []
    for r in range(5, days.size):
        rp = find_places(SEG, runs[:, :, r], runs[:, :, :r], days[:r], days[r], cls, segment_m=10.0, params=PARAMS)
        events, _, next_id = advance_places(known, rp, run_id=r, day=days[r], covered_m=(10_000.0, 13_000.0),
                                            params=LifecycleParams(), next_id=next_id, place_params=PARAMS,
                                            actions=[tamping])
        log += [(r, e.kind, e.place_id, e.action_id) for e in events]
    hard = next(k for k in known if k.direction == 1 and k.start_m <= 12_020 <= k.end_m)
    assert hard.listed and not hard.active and hard.actions == [77]
    assert (11, "repaired", hard.id, 77) in log  # day 154: the first run after the tamping
    effect = [k for k in known if k.direction == -1 and k.start_m < tamping.end_m and k.end_m > tamping.start_m]
    assert effect and all(k.explained_by == 77 and not k.listed for k in effect)
    assert not [e for e in log if e[2] in {k.id for k in effect}]  # its effect raised no alert


def _ramp_line_runs(seed: int, n_runs: int, change=None):
    """Segment rows of ``n_runs`` runs over km 10–13 with speed ramps (65 → cruise over the first 500 m,
    cruise → 60 km/h over the last 400 m, cruise 120 km/h ± 10 %): ``ln A`` follows a curved speed law
    plus the track's own variation per rail and noise; ``change(run)`` adds to the track."""
    rng = np.random.default_rng(seed)
    x = (SEG + 0.5) * 10.0
    rails = {w: _track(np.random.default_rng(seed + 100 + int(w[1]))) for w in ("11", "12", "41", "42")}
    la, speed = np.empty((W, SEG.size, n_runs)), np.empty((W, SEG.size, n_runs))
    cruise = 120.0 * (1 + 0.1 * np.linspace(-1, 1, n_runs))[rng.permutation(n_runs)]
    for r in range(n_runs):
        v_in = 65.0 + (cruise[r] - 65.0) * np.clip((x - 10_000.0) / 500.0, 0, 1)
        v = np.where(x < 12_600.0, v_in, cruise[r] + (60.0 - cruise[r]) * np.clip((x - 12_600.0) / 400.0, 0, 1))
        v = v / 3.6
        law = 1.4 * np.log(v / 30.0) + 0.3 * np.log(v / 30.0) ** 2
        level = rng.normal(0, 0.02)
        for i, w in enumerate(rails):
            la[i, :, r] = law + rails[w] + level + rng.normal(0, NOISE, SEG.size) + (0 if change is None else change(r))
            speed[i, :, r] = v * (1 + rng.normal(0, 0.003, SEG.size))
    return la, speed


def _index_of_runs(la, speed, upto: int):
    from app.analysis.condition.segment_curves import fit_segment_curves

    cls = np.full(SEG.size, "b91", dtype=object)
    wheels = ("11", "12", "41", "42")
    cols = [np.concatenate(c) for c in zip(*[(SEG, la[i, :, r], speed[i, :, r], np.full(SEG.size, r),
                                              np.full(SEG.size, w), cls) for r in range(upto) for i, w in
                                             enumerate(wheels)], strict=True)]
    curves = fit_segment_curves(*cols)
    runs_last = np.moveaxis(segment_index(np.moveaxis(la[:, :, :upto], 2, 1), np.moveaxis(speed[:, :, :upto], 2, 1),
                                          cls, curves), 1, 2)
    return runs_last, cls


def test_a_uniform_line_with_speed_ramps_gives_no_place_but_ln_a_would():
    la, speed = _ramp_line_runs(41, 12)
    index, cls = _index_of_runs(la, speed, 12)
    days = np.arange(12) * 14.0
    for r in (6, 9, 11):
        rp = find_places(SEG, index[:, :, r], index[:, :, :r], days[:r], days[r], cls, segment_m=10.0, params=PARAMS)
        assert len(rp) == 0, (r, rp.places.start_m)
    # without the speed conditioning (ln A against its own median over the line) the ramps read as track
    raw = la - np.median(la[:, :, :12], axis=(0, 1))[None, None, :]
    rp = find_places(SEG, raw[:, :, 11], raw[:, :, :11], days[:11], days[11], cls, segment_m=10.0, params=PARAMS)
    assert len(rp) >= 2 and rp.places.start_m.min() < 10_500.0 and rp.places.end_m.max() > 12_600.0


@pytest.mark.parametrize(("start", "size"), [(10_203.0, np.log(0.8)), (11_507.5, np.log(0.8)),
                                             (11_995.0, np.log(1.25))])
def test_a_20m_change_on_a_ramp_or_at_cruise_is_one_place_within_5m(start, size):
    la, speed = _ramp_line_runs(42, 12, lambda r: _box(start, start + 20.0, size) if r == 11 else 0.0)
    index, cls = _index_of_runs(la, speed, 12)
    days = np.arange(12) * 14.0
    rp = find_places(SEG, index[:, :, 11], index[:, :, :11], days[:11], days[11], cls, segment_m=10.0, params=PARAMS)
    assert len(rp) == 1
    assert rp.places.direction[0] == np.sign(size) and rp.places.evidence[0] & EVIDENCE_STEP
    assert abs(rp.places.centre_m[0] - (start + 10.0)) < 5.0
    assert rp.change[0] == pytest.approx(size, abs=0.07)
    assert rp.tier[0] == 1  # |change| 0.22 in [0.10, 0.30): alert


def test_a_trend_alone_makes_a_watch_place_only_where_it_reaches_the_alert_limit_soon():
    rng = np.random.default_rng(14)
    base = _track(rng) * 0.2
    spot = _box(12_000.0, 12_040.0, 1.0)
    days = np.arange(13) * 14.0
    cls = np.full(SEG.size, "b91", dtype=object)

    def newest(start: float) -> object:
        runs = _runs(rng, base, 13, lambda r: spot * (start + 0.35 * (days[r] - days[-1]) / 365.25))
        return find_places(SEG, runs[:, :, -1], runs[:, :, :-1], days[:-1], days[-1], cls, segment_m=10.0,
                           params=PARAMS)

    # growing 0.35 a year (0.08 over the history's median: no step): at 0.16 it reaches b91's 0.25 in
    # ~95 days (watch); at 0.05 in ~210 days (not yet, unless the horizon is a year)
    soon = newest(0.16)
    assert len(soon) == 1 and soon.places.evidence[0] == EVIDENCE_TREND and soon.tier[0] == 0
    assert soon.rate_per_year[0] == pytest.approx(0.35, rel=0.2)
    assert len(newest(0.05)) == 0
    assert len(find_places(*_trend_args(rng, base, spot, days, cls), segment_m=10.0,
                           params=PlaceParams(PARAMS.levels, PARAMS.changes, watch_days=365.0))) == 1
    with pytest.raises(ValueError, match="watch_days"):
        PlaceParams(PARAMS.levels, PARAMS.changes, watch_days=0.0)


def test_a_trend_on_rough_rails_is_graded_by_its_change_against_its_matched_passes():
    """Issue 33: the real line's place developing on pads read −0.55 ± 0.61 in the run that found it by its
    trend: watch by its level (graded on a 1-σ that is mostly the rails' response at the sleeper spacing),
    while its change against its own passes (−0.24) is what the rails' response, the same at every pass,
    leaves out. A trend's change so far grades it as a step's does: here alert (|change| ≥ 0.10)."""
    rng = np.random.default_rng(33)
    rails = rng.normal(0, 0.4, (W // 2, SEG.size)).repeat(2, axis=0)  # each rail's response, the same every run
    base = _track(rng) * 0.3
    spot = _box(12_000.0, 12_040.0, 1.0)
    days = np.arange(13) * 14.0
    runs = _runs(rng, base, 13, lambda r: spot * -0.8 * max(days[r] - days[3], 0.0) / 365.25) + rails[:, :, None]
    cls = np.full(SEG.size, "b91", dtype=object)
    rp = find_places(SEG, runs[:, :, -1], runs[:, :, :-1], days[:-1], days[-1], cls, segment_m=10.0, params=PARAMS,
                     index_sd=np.full(runs[:, :, -1].shape, 0.5), history_sd=np.full(runs[:, :, :-1].shape, 0.2))
    assert len(rp) >= 1 and all(e == EVIDENCE_TREND for e in rp.places.evidence)  # no step: its 1-σ is too wide
    assert all(12_000.0 <= c <= 12_040.0 for c in rp.places.centre_m)
    assert np.all(rp.change <= -0.10) and np.all(rp.rate_per_year < -0.5)
    assert np.all(rp.level_tier == 0)  # its level alone: watch
    assert np.all(rp.change_tier == 1) and np.all(rp.tier == 1)


def _trend_args(rng, base, spot, days, cls):
    runs = _runs(rng, base, days.size, lambda r: spot * (0.05 + 0.35 * (days[r] - days[-1]) / 365.25))
    return SEG, runs[:, :, -1], runs[:, :, :-1], days[:-1], days[-1], cls


def test_a_place_whose_size_is_within_its_uncertainty_is_not_in_the_top_tier():
    """The tier rests on the size in units of the healthy scatter at its pass (``graded_level``: the limits
    stand for σ0 = 0.25 / 3.3 = 0.076; a pass uncertain by sd has √(σ0² + sd²)): a lasting hard spot of 0.70
    (immediate: ≥ 0.625) stated ±0.05 is graded on 0.58 (intervention), ±0.15 on 0.32 (alert); ±0.3 leaves 0.17,
    within what its uncertainty gives the typical track (below the alert limit 0.25): no anomaly at all. Without
    a stated 1-sigma (NaN) it is immediate as before."""
    rng = np.random.default_rng(11)
    track = _track(rng) * 0.3 + _box(11_000.0, 11_030.0, 0.70)  # lasting, in the history too
    hist = _runs(rng, track, 8)
    new = _runs(rng, track, 1)[:, :, 0]
    cls = np.full(SEG.size, "b91", dtype=object)
    tiers = {}
    for sd in (np.nan, 0.05, 0.15, 0.3):
        rp = find_places(SEG, new, hist, np.arange(8.0), 8.0, cls, segment_m=10.0, params=PARAMS,
                         index_sd=np.full(new.shape, sd), history_sd=np.full(hist.shape, sd))
        if sd == 0.3:
            assert len(rp) == 0
            continue
        assert len(rp) == 1 and rp.places.evidence[0] == EVIDENCE_ANOMALY
        assert rp.level[0] == pytest.approx(0.70, abs=0.03)
        assert rp.severity[0] == pytest.approx(abs(rp.level[0]) / 0.25)
        if np.isnan(sd):
            assert np.isnan(rp.level_sd[0]) and np.isnan(rp.severity_sd[0])
        else:
            assert rp.level_sd[0] == pytest.approx(sd) and rp.severity_sd[0] == pytest.approx(sd / 0.25)
        tiers[sd] = int(rp.tier[0])
    assert tiers[np.nan] == 3 and tiers[0.05] == 2 and tiers[0.15] == 1


def test_a_change_within_its_uncertainty_is_graded_on_its_lower_bound_and_a_grinding_widens_it():
    """A new −30 % step (change 0.36: intervention) where the new run states more than the history: the excess
    enters the step's denominator (shared by the wheels) and the change's tier rests on change − 1-sigma;
    across a recorded grinding on its segments the history's stated 1-sigma enters too: no step is found,
    while the same stated 1-sigma without a grinding repeats and changes nothing."""
    rng = np.random.default_rng(12)
    track = _track(rng) * 0.3
    hist = _runs(rng, track, 8)
    step = _box(11_500.0, 11_530.0, np.log(0.70))
    new = _runs(rng, track, 1, lambda r: step)[:, :, 0]
    cls = np.full(SEG.size, "b91", dtype=object)
    plain = find_places(SEG, new, hist, np.arange(8.0), 8.0, cls, segment_m=10.0, params=PARAMS)
    assert len(plain) == 1 and plain.change_tier[0] == 2 and plain.tier[0] == 2
    hist_sd = np.full(hist.shape, 0.01)
    new_sd = np.full(new.shape, 0.01)
    new_sd[:, (SEG >= 1145) & (SEG < 1158)] = 0.07  # this run states more there (another vehicle, say)
    wide = find_places(SEG, new, hist, np.arange(8.0), 8.0, cls, segment_m=10.0, params=PARAMS,
                       index_sd=new_sd, history_sd=hist_sd)
    assert len(wide) == 1 and wide.places.evidence[0] & EVIDENCE_STEP
    assert abs(wide.change_z[0]) < abs(plain.change_z[0]) / 3  # sqrt(0.07² − 0.01²) ≈ 0.069 joins 0.02/√4
    assert wide.change_sd[0] == pytest.approx(0.07, abs=0.01)
    assert wide.change[0] == pytest.approx(plain.change[0])
    assert wide.change_tier[0] == 1 and wide.tier[0] == 1  # 0.36 − 0.07 < 0.30
    ground = np.where((SEG >= 1140) & (SEG < 1160), 7.5, np.nan)  # ground between the history and the run
    sd = {"index_sd": np.full(new.shape, 0.1), "history_sd": np.full(hist.shape, 0.1)}
    across = find_places(SEG, new, hist, np.arange(8.0), 8.0, cls, segment_m=10.0, params=PARAMS, surface_days=ground,
                         **sd)
    assert not any(e & EVIDENCE_STEP for e in across.places.evidence)  # 0.36 / sqrt(0.1² + 0.1²) ≈ 2.5
    same = find_places(SEG, new, hist, np.arange(8.0), 8.0, cls, segment_m=10.0, params=PARAMS, **sd)
    assert len(same) == 1 and same.change_tier[0] == 2  # the same sd without a grinding: repeats, no widening


def test_after_a_tamping_the_history_starts_anew():
    """The demo's case: a place growing harder (+1.2 a year) tamped to 15 % below typical track between runs 6
    and 7. Read across the tamping, the runs after it make a soft place — its change against the runs
    before and its trend through them measure the work; with the tamping's day on its segments
    (``support_days``) the step and the trend tests see only the runs since, and nothing is found there."""
    from app.analysis.condition.interventions import latest_action_days, since_actions

    rng = np.random.default_rng(21)
    track = _track(rng) * 0.3
    spot = _box(12_000.0, 12_040.0, 1.0)
    extent = _box(11_900.0, 12_100.0, 1.0)
    days = np.arange(10) * 14.0
    tamped = 77.0

    def change(r: int) -> np.ndarray:
        if days[r] < tamped:
            return spot * (0.3 + 1.2 * days[r] / 365.25)
        return extent * np.log(0.85) + extent * 0.1 * (days[r] - tamped) / 365.25

    runs = _runs(rng, track, 10, change)
    cls = np.full(SEG.size, "b91", dtype=object)
    args = (SEG, runs[:, :, -1], runs[:, :, :-1], days[:-1], days[-1], cls)
    across = find_places(*args, segment_m=10.0, params=PARAMS)
    on = [i for i in range(len(across)) if 11_900 <= across.places.centre_m[i] <= 12_100]
    assert on and all(across.places.direction[i] < 0 for i in on)  # the work read as a soft place
    support = latest_action_days(SEG, 10.0, np.array([11_900.0]), np.array([12_100.0]), np.array([tamped]), days[-1])
    assert np.isfinite(support[(SEG >= 1190) & (SEG < 1210)]).all() and np.isnan(support[SEG < 1170]).all()
    since = find_places(*args, segment_m=10.0, params=PARAMS, support_days=support)
    assert not [i for i in range(len(since)) if 11_850 <= since.places.centre_m[i] <= 12_150]
    # the history as the tests see it: the runs before the tamping gone on its segments only
    h = since_actions(runs[:, :, :-1], days[:-1], support)
    k = int(np.searchsorted(SEG, 1200))
    assert np.isnan(h[:, k, days[:-1] < tamped]).all() and np.isfinite(h[:, k, days[:-1] > tamped]).all()
    assert np.array_equal(h[:, 0, :], runs[:, 0, :-1])
    with pytest.raises(ValueError, match="segments, runs"):
        since_actions(runs[:, :, :-1], days[:-2], support)
