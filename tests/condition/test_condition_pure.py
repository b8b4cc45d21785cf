"""The pure numerics of the condition store: segment statistics and the change tests."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.condition import (
    ChangeParams,
    combine_wheels,
    detect_changes,
    level_offsets,
    nan_median,
    pooled_spread,
    robust_spread,
    segment_stats,
    speed_matched,
    step_change,
    trend_change,
)


def test_segment_stats_match_a_brute_force_per_segment():
    rng = np.random.default_rng(0)
    pos = (np.arange(2000) + 0.5) * 0.25 + 1000.0
    amp = rng.lognormal(0, 0.3, pos.size)
    amp[rng.random(pos.size) < 0.1] = np.nan
    amp[300:420] = -1.0  # not valid: a gap of 30 m
    speed = rng.uniform(20, 40, pos.size)
    index = np.log(np.where(amp > 0, amp, np.nan))
    st = segment_stats(pos, amp, speed, index, segment_m=10.0, min_valid_fraction=0.5)
    seg = np.floor(pos / 10.0)
    for k, s in enumerate(st.seg):
        m = (seg == s) & np.isfinite(amp) & (amp > 0)
        assert st.n_valid[k] == m.sum() >= 20
        assert st.amp_mean[k] == pytest.approx(amp[m].mean())
        assert st.amp_p95[k] == pytest.approx(np.percentile(amp[m], 95))
        assert st.speed_mean[k] == pytest.approx(speed[m].mean())
        assert st.index[k] == pytest.approx(np.log(amp[m]).mean())
        assert np.isnan(st.index_sd[k])  # the spread of the bins is not an uncertainty: none stated
    covered = {int(s) for s in np.unique(seg)}
    assert set(st.seg.tolist()) < covered  # the gap's segments are left out
    with pytest.raises(ValueError, match="segment_m"):
        segment_stats(pos, amp, speed, index, segment_m=0.0)
    with pytest.raises(ValueError, match="speed_mps"):
        segment_stats(pos, amp, speed[:-1], index, segment_m=10.0)


def test_nan_median_and_robust_spread_agree_with_numpy():
    rng = np.random.default_rng(1)
    h = rng.normal(0, 0.05, (300, 25))
    h[rng.random(h.shape) < 0.3] = np.nan
    h[0] = np.nan
    with pytest.warns(RuntimeWarning):
        want = np.nanmedian(h, axis=1)
    np.testing.assert_allclose(nan_median(h), want, equal_nan=True)
    med, spread = robust_spread(rng.normal(0, 0.05, (2000, 40)))
    assert np.median(spread) == pytest.approx(0.05, rel=0.05)  # consistent with σ for normal noise
    assert np.all(np.isnan(robust_spread(h)[1][0:1]))


def test_speed_matching_recovers_the_exponent_and_keeps_close_runs():
    rng = np.random.default_rng(2)
    n_seg, n_run = 400, 30
    level = rng.normal(0, 0.3, n_seg)[:, None]
    v = 30 * (1 + rng.uniform(-0.2, 0.2, (n_seg, n_run)))
    h = level + 1.5 * np.log(v) + rng.normal(0, 0.02, (n_seg, n_run))
    m = speed_matched(h, v, np.full(n_seg, 30.0), tolerance=0.1)
    assert m.exponent == pytest.approx(1.5, abs=0.05)
    kept = np.isfinite(m.history)
    assert np.all(np.abs(v[kept] / 30.0 - 1) <= 0.1) and kept.sum() == m.n_matched.sum()
    moved = m.history[kept] - np.broadcast_to(level, h.shape)[kept]
    assert np.std(moved - 1.5 * np.log(30.0)) < 0.03  # moved to 30 m/s


def test_step_scores_are_calibrated_and_find_a_change():
    rng = np.random.default_rng(3)
    p = ChangeParams(min_history=8)
    h = rng.normal(0, 0.04, (20_000, 30))
    x = rng.normal(0, 0.04, 20_000)
    x[:100] += 0.18
    r = step_change(h, x, p)
    null = r.z[100:]
    assert np.std(null) == pytest.approx(1.0, abs=0.1)
    assert np.mean(np.abs(null) >= p.step_z) < 1e-3
    assert np.mean(r.z[:100] >= p.step_z) > 0.2  # one wheel alone: weak; the wheels together are strong
    assert np.all(np.isnan(step_change(h[:, :5], x, p).z))  # too little history: no test


def test_pooled_spread_tames_small_histories():
    rng = np.random.default_rng(4)
    h = rng.normal(0, 0.04, (5000, 8))
    x = rng.normal(0, 0.04, 5000)
    seg = np.arange(5000)
    p = ChangeParams(min_history=8)
    own = step_change(h, x, p)
    pooled = step_change(h, x, p, seg=seg, segment_m=10.0)
    assert np.mean(np.abs(own.z) >= 4.5) > 3 * np.mean(np.abs(pooled.z) >= 4.5)
    s = pooled_spread(np.array([0.01, 0.04, 0.04]), np.array([8, 8, 8]), np.array([0, 1, 2]), segment_m=10.0,
                      block_m=1000.0, prior_runs=8)
    assert s[0] == pytest.approx(np.sqrt((0.01**2 + 0.04**2) / 2))


def test_level_offsets_remove_a_run_wide_offset_but_not_a_local_change():
    seg = np.arange(300)
    dev = np.zeros((300, 3))
    dev[:, 1] = 0.05  # run 1 is 5 % higher everywhere (calibration)
    dev[10:12, 2] = 0.2  # run 2 changed locally
    off = level_offsets(dev, seg, segment_m=10.0, block_m=1000.0)
    np.testing.assert_allclose(off[:, 1], 0.05)
    np.testing.assert_allclose(off[:, 2], 0.0)


def test_trend_finds_a_steady_degradation_and_not_noise():
    rng = np.random.default_rng(5)
    days = np.arange(200.0)
    n = 2000
    h = rng.normal(0, 0.02, (n, 200))
    h[:100] += 0.10 / 365.25 * np.clip(days - 100, 0, None)  # 10 %/year from day 100
    x = rng.normal(0, 0.02, n)
    x[:100] += 0.10 / 365.25 * 100
    r = trend_change(days, h, x, 200.0, ChangeParams())
    assert np.median(r.z[:100]) > 4.5  # one wheel after 100 days; the wheels combined find it surely
    assert np.mean(np.abs(r.z[100:]) >= 4.5) < 0.005
    assert np.nanmedian(r.rate_per_year[:100]) == pytest.approx(0.075, abs=0.02)  # half the window flat
    assert np.isnan(r.rate_per_year[100:]).mean() > 0.5  # no rate where nothing goes on


def test_detect_changes_and_combining_wheels():
    rng = np.random.default_rng(6)
    seg = np.arange(1000, 1500)
    zs = []
    for _ in range(4):
        v = np.full((seg.size, 30), 30.0)
        h = rng.normal(0, 0.03, v.shape)
        x = rng.normal(0, 0.03, seg.size) + 0.02  # this run is 2 % higher everywhere
        x[100] += 0.18
        c = detect_changes(h, v, np.arange(30.0), x, np.full(seg.size, 30.0), 30.0, seg, segment_m=10.0)
        zs.append(c.change_z)
        assert abs(np.median(c.change)) < 0.01  # the run's level is taken out
    combined, agree = combine_wheels(np.array(zs), 2.0)
    assert combined[100] > 8 and agree[:, 100].sum() >= 3
    assert np.mean(np.abs(np.delete(combined, 100)) >= 4.5) < 0.01
    with pytest.raises(ValueError, match="z"):
        combine_wheels(np.zeros(3), 2.0)


def test_a_matched_pass_is_by_the_same_vehicle():
    """Two vehicles whose responses differ segment by segment (0.25 ln units): a run of the second vehicle
    against a history of mostly the first flags a quarter of its segments; with the history's vehicles the
    other vehicle's passes are brought to its own (the segment's offset, its uncertainty in the score) and it
    flags almost none, while a real −0.3 step is still found; with enough passes of its own only they count;
    a vehicle with fewer than 2 passes is not tested."""
    from app.analysis.condition.change import vehicle_matched

    rng = np.random.default_rng(12)
    seg = np.arange(1000, 1300)
    n_runs = 14
    own = rng.normal(0, 0.25, seg.size)  # the second vehicle's response, against the first's
    labels = np.array(["V2" if k in (3, 8, 12) else "V1" for k in range(n_runs)], dtype=object)
    h = rng.normal(0, 0.03, (seg.size, n_runs)) + np.where(labels == "V2", 1.0, 0.0)[None, :] * own[:, None]
    x = own + rng.normal(0, 0.03, seg.size)
    x[150] -= 0.3
    v = np.full(h.shape, 30.0)
    args = (h, v, np.arange(float(n_runs)), x, np.full(seg.size, 30.0), float(n_runs), seg)
    mixed = detect_changes(*args, segment_m=10.0)
    assert np.mean(np.abs(np.nan_to_num(mixed.change_z)) >= 4.5) > 0.1
    c = detect_changes(*args, segment_m=10.0, history_vehicle=labels, vehicle="V2")
    z = np.nan_to_num(c.change_z)
    assert z[150] <= -4.5 and np.mean(np.abs(np.delete(z, 150)) >= 4.5) < 0.01
    # a vehicle's own passes alone where it has enough; none to test a vehicle without 2 passes
    hv, extra, ok = vehicle_matched(h, np.where(labels == "V2", "V1", "V2").astype(object), "V2", min_history=8,
                                    min_spread=0.005)
    assert ok.all() and np.all(extra == 0) and np.isnan(hv[:, [3, 8, 12]]).all()
    _, _, none = vehicle_matched(h, np.array(["V1"] * n_runs, dtype=object), "V3", min_history=8, min_spread=0.005)
    assert not none.any()
    c3 = detect_changes(*args, segment_m=10.0, history_vehicle=np.array(["V1"] * n_runs, dtype=object), vehicle="V3")
    assert np.isnan(c3.change_z).all()
    same = detect_changes(*args, segment_m=10.0, history_vehicle=labels, vehicle=None)
    assert np.array_equal(np.nan_to_num(same.change_z), np.nan_to_num(mixed.change_z))


def test_change_params_are_validated():
    with pytest.raises(ValueError, match="step_z"):
        ChangeParams(step_z=0)
    with pytest.raises(ValueError, match="history_runs"):
        ChangeParams(min_history=10, history_runs=5)


def test_action_effect_before_after_and_how_long_it_lasted():
    from app.analysis.condition.maintenance_effect import action_effect

    rng = np.random.default_rng(8)
    days = np.arange(0.0, 400.0)
    level = np.where(days < 100, 0.0, np.minimum(-0.2 + 0.4 * (days - 100) / 365.25, 0.0))
    values = level + rng.normal(0, 0.01, days.size)
    e = action_effect(days, values, 99.5)
    assert e.n_before == 90 and e.n_after == 30
    assert e.recovery == pytest.approx(-0.2 + 0.4 * 15 / 365.25, abs=0.01)  # median of the first 30 days
    assert e.slope_after_per_year == pytest.approx(0.3, abs=0.1)  # the regrowth, levelling off at 0
    half = 0.5 * abs(e.recovery) / 0.4 * 365.25 + 15  # the level halfway back
    assert e.lasted_days_observed == pytest.approx(half, abs=10)
    assert e.lasted_days_projected is not None and e.lasted_days_projected > 0
    none = action_effect(days[:90], values[:90], 99.5)  # no run after: no recovery
    assert none.recovery is None and none.n_after == 0
    with pytest.raises(ValueError, match="regain_fraction"):
        action_effect(days, values, 99.5, regain_fraction=0)


def test_action_effect_at_matched_speed_whatever_the_speed_mix_and_split_by_action_type():
    """Runs at two speeds whose extent reads 0.3 ln units apart: a −20 % tamping (ln 0.8) with one slow run in
    the before window and only slow runs after it reads the speed mix as well from the medians; at matched
    speed each run after is compared with the runs before it at its speed (the place's own baseline), within
    its 1 σ interval. A grinding: its change across the work is the rail surface's response, the support's
    change (since it, against the new surface's own baseline) is 0; a tamping's support change is its recovery.
    How long it held is never said beyond the runs after it."""
    from app.analysis.condition.maintenance_effect import (
        action_effect,
        matched_change,
        split_effect,
    )

    rng = np.random.default_rng(3)
    days = np.arange(0.0, 200.0, 5.0)
    fast = (days < 100) & (days > 10)  # before: all fast but two; after: slow
    speeds = np.where(fast, 40.0, 26.0) * (1 + rng.normal(0, 0.01, days.size))
    truth = np.log(0.8)
    level = np.where(speeds > 33, 0.3, 0.0) + np.where(days > 100, truth, 0.0)
    values = level + rng.normal(0, 0.02, days.size)
    mixed = action_effect(days, values, 100.0)
    assert abs(mixed.recovery - truth) > 0.2  # the speed mix, not the tamping
    e = action_effect(days, values, 100.0, speeds=speeds)
    assert e.recovery == pytest.approx(truth, abs=0.03)
    assert 0 < e.recovery_sigma < 0.05 and e.recovery_low < e.recovery < e.recovery_high
    assert e.recovery_low - 2 * e.recovery_sigma < truth < e.recovery_high + 2 * e.recovery_sigma
    assert e.followed_days == pytest.approx(195.0 - 100.0)
    sp = split_effect("tamping", days, values, speeds, 100.0, e)
    assert sp.support_change == e.recovery and not sp.rail_surface and sp.rail_surface_change is None
    assert sp.support_low == e.recovery_low
    assert matched_change(np.array([0.1]), np.array([40.0]), np.array([0.0]), np.array([26.0])) is None
    ground = np.where(days > 100, -0.4, 0.0) + rng.normal(0, 0.01, days.size)
    g = action_effect(days, ground, 100.0, speeds=speeds)
    sg = split_effect("grinding", days, ground, speeds, 100.0, g)
    assert sg.rail_surface and sg.rail_surface_change == pytest.approx(-0.4, abs=0.03)
    assert sg.support_change == pytest.approx(0.0, abs=0.03)
    assert sg.support_low < sg.support_change < sg.support_high
    # a slow regrowth after it: projected to be half lost far beyond the 95 days the runs saw — not said
    slow = values + np.where(days > 100, 0.05 * (days - 100) / 365.25, 0.0)
    held = action_effect(days, slow, 100.0, speeds=speeds)
    assert held.slope_after_per_year is not None and held.lasted_days_projected is None
    assert held.lasted_days_observed is None


def test_maintenance_effect_compares_a_run_with_its_own_vehicles_passes():
    """On rough rails the rails' response differs by vehicle as by speed: two vehicles reading the same extent
    0.12 apart, alternating so that the grinding's first window holds one run of each and the later runs mostly
    the first vehicle. Across the vehicles the support's change reads the vehicle mix; compared with each
    vehicle's own passes it is the truth (0), and a run whose vehicle has no pass before falls back to all."""
    from app.analysis.condition.maintenance_effect import (
        action_effect,
        matched_change,
        split_effect,
    )

    days = np.arange(0.0, 300.0, 15.0) + 2.0
    veh = np.array(["V2" if k % 3 == 1 else "V1" for k in range(days.size)], dtype=object)
    speeds = np.full(days.size, 40.0)
    ground = np.where(days > 100, -0.3, 0.0)
    values = ground + np.where(veh == "V2", 0.12, 0.0)
    first = (days > 100) & (days <= 130)
    assert sorted(veh[first].tolist()) == ["V1", "V2"]
    e = action_effect(days, values, 100.0, speeds=speeds, vehicles=veh)
    assert e.recovery == pytest.approx(-0.3, abs=1e-9)
    mixed = split_effect("grinding", days, values, speeds, 100.0, action_effect(days, values, 100.0, speeds=speeds))
    own = split_effect("grinding", days, values, speeds, 100.0, e, vehicles=veh)
    assert abs(mixed.support_change) > 0.05
    assert own.support_change == pytest.approx(0.0, abs=1e-9) and own.rail_surface_change == pytest.approx(-0.3)
    # a vehicle without a pass before: against every pass at its speed
    got = matched_change(np.array([0.0, 0.2]), np.array([40.0, 40.0]), np.array([0.5]), np.array([40.0]),
                         before_vehicle=np.array(["V1", "V2"], dtype=object),
                         after_vehicle=np.array(["V3"], dtype=object))
    assert got == pytest.approx(0.4)
    assert matched_change(np.array([0.0, 0.2]), np.array([40.0, 40.0]), np.array([0.5]), np.array([40.0]),
                          before_vehicle=np.array(["V1", "V2"], dtype=object),
                          after_vehicle=np.array(["V2"], dtype=object)) == pytest.approx(0.3)
    with pytest.raises(ValueError, match="vehicles"):
        action_effect(days, values, 100.0, speeds=speeds, vehicles=veh[:3])


def test_store_index_sd_is_segment_sd_over_the_mean_amplitude():
    """The store's stated 1-σ of a segment's ln A: segment_sd of the valid bins' sd (and shared part) on the
    aligned axis over their mean amplitude (delta method); NaN where no bin states one."""
    from app.analysis.uncertainty import segment_sd
    from app.condition.index import store_index_sd

    rng = np.random.default_rng(3)
    bins = np.arange(4000, 4800)
    shift = 3.3
    pos = (bins + 0.5) * 0.25 + shift
    amp = rng.lognormal(0.0, 0.2, bins.size)
    amp[50:90] = np.nan
    sd = 0.3 * amp * rng.uniform(0.5, 1.5, bins.size)
    sd[400:440] = np.nan  # no stated 1-sigma there
    shared = 0.5 * sd
    st = segment_stats(pos, amp, np.full(bins.size, 30.0), np.log(amp), segment_m=10.0)
    got = store_index_sd(pos, amp, sd, shared, st.seg, segment_m=10.0, bin_length_m=0.25, resolution_m=3.0,
                         filter_order=2)
    ok = np.isfinite(amp) & np.isfinite(sd)
    aligned = np.floor(pos / 0.25).astype(np.int64)
    segs, ref = segment_sd(aligned[ok], sd[ok], 10.0, 0.25, 3.0, 2, shared=shared[ok])
    seg_of = np.floor(pos[ok] / 10.0).astype(np.int64)
    want = {g: r / amp[ok][seg_of == g].mean() for g, r in zip(segs.tolist(), ref.tolist(), strict=True)}
    assert np.all(np.isfinite(got)) and np.all(got > 0)
    for s_, g in zip(st.seg.tolist(), got.tolist(), strict=True):
        assert g == pytest.approx(want[s_], rel=1e-12)
    # a 10 m mean of bins correlated over ~4 m: between sd/sqrt(n bins) and the bins' sd
    rel = np.nanmedian(sd / amp)
    assert rel / np.sqrt(40) < np.median(got) < rel
    assert np.all(np.isnan(store_index_sd(pos, amp, None, None, st.seg, segment_m=10.0, bin_length_m=0.25)))
    nan_sd = np.full(bins.size, np.nan)
    assert np.all(np.isnan(store_index_sd(pos, amp, nan_sd, nan_sd, st.seg, segment_m=10.0, bin_length_m=0.25)))


def test_the_rolling_history_gives_each_earlier_run_on_the_asked_segments():
    """RollingHistory.matrix: a run over the same segments as asked (taken whole) and runs over other
    segments (matched segment by segment, NaN where they have none), oldest first."""
    from app.analysis.condition import RollingHistory
    from app.analysis.condition.segments import SegmentStats

    def stats(seg, base):
        seg = np.asarray(seg, dtype=np.int64)
        f = base + np.arange(seg.size, dtype=np.float64)
        return SegmentStats(seg, np.full(seg.size, 40), np.exp(f), np.exp(f), 30.0 + f, f, 0.01 * f)

    h = RollingHistory()
    h.append(0.0, {10.0: {"11": stats([3, 4, 5, 6], 1.0)}})
    h.append(1.0, {10.0: {"11": stats([4, 5, 6, 7], 10.0)}})
    h.append(2.0, {10.0: {"11": stats([3, 4, 5, 6], 20.0)}})
    m = h.matrix(10.0, "11", np.array([3, 4, 5, 6]), trend=False)
    nan = np.nan
    np.testing.assert_array_equal(m.index, [[1, nan, 20], [2, 10, 21], [3, 11, 22], [4, 12, 23]])
    np.testing.assert_array_equal(m.speed, 30.0 + m.index)
    np.testing.assert_allclose(m.index_sd, 0.01 * m.index)
    np.testing.assert_array_equal(m.days, [0.0, 1.0, 2.0])
    assert h.matrix(10.0, "12", np.array([3, 4]), trend=False).index.shape == (2, 0)


def test_after_an_action_on_the_support_the_store_tests_only_the_runs_since():
    """assess_run's ``support``: a tamping over km 0.40–0.60 between the history and the newest run lowers the
    index there by 0.3 — read across it, its segments are flagged (and the run level they shift can flag others);
    with the tamping given, the segments it covers (and its margin) have no run since to test against and
    nothing is flagged, while the rest of the line is tested as before."""
    from app.analysis.condition import RollingHistory, assess_run
    from app.analysis.condition.segments import SegmentStats

    rng = np.random.default_rng(33)
    seg = np.arange(100, dtype=np.int64)
    track = rng.normal(0.0, 0.1, seg.size)

    def run(extra: np.ndarray) -> dict:
        f = track + extra + rng.normal(0.0, 0.02, seg.size)
        wheels = {}
        for w in ("11", "12", "41", "42"):
            g = f + rng.normal(0.0, 0.02, seg.size)
            wheels[w] = SegmentStats(seg, np.full(seg.size, 40), np.exp(g), np.exp(g), np.full(seg.size, 30.0), g,
                                     np.full(seg.size, np.nan))
        return {10.0: wheels}

    hist = RollingHistory()
    for day in range(8):
        hist.append(float(day * 14), run(np.zeros(seg.size)))
    tamped = np.where((seg >= 40) & (seg < 60), np.log(0.74), 0.0)
    new = run(tamped)
    action = (np.array([400.0]), np.array([600.0]), np.array([7.5 * 14]))
    across = assess_run(new, hist, 8 * 14.0, support=None)
    steps = sorted({f.seg for f in across.flags if f.kind == "step"})
    assert set(range(42, 58)) <= set(steps), steps
    since = assess_run(new, hist, 8 * 14.0, support=action, intervention_margin_m=14.2)
    assert [f for f in since.flags if f.kind == "step"] == []
    n = since.changes[10.0]["11"].n_history
    assert (n[(seg >= 40) & (seg < 60)] == 0).all() and (n[seg < 30] > 0).all() and (n[seg >= 70] > 0).all()
