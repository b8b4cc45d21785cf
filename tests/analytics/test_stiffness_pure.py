"""Pure analyses of app.analysis.stiffness on synthetic data with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.stiffness.alignment import align_runs, segment_table
from app.analysis.stiffness.maintenance import box_stats, count_actions, maintenance_correlation
from app.analysis.stiffness.regression import decimate_indices, linear_fit
from app.analysis.stiffness.speed_norm import fit_speed_exponent, normalise_amplitude
from app.analysis.stiffness.subsidence import bin_means, fit_subsidence, predict_subsidence
from app.analysis.stiffness.superstructure import assign_sections, flag_segments
from app.analysis.stiffness.unsprung_mass import fit_unsprung_mass


def _smooth(rng, n, width):
    k = np.hanning(width)
    return np.convolve(rng.standard_normal(n + width - 1), k / np.sqrt(k @ k), "valid")


def test_hac_intervals_cover_under_autocorrelation():
    """Over 200 series with strongly autocorrelated errors, the 95 % HAC interval covers the
    true slope about 95 % of the time, the plain one (lag 0) far less often."""
    rng = np.random.default_rng(1)
    hit_hac = hit_plain = 0
    for _ in range(200):
        x = _smooth(rng, 2000, 80)
        y = 0.7 * x + 0.3 + _smooth(rng, 2000, 80)
        fh = linear_fit(x, y, hac_lag=200)
        hit_hac += fh.slope_ci[0] <= 0.7 <= fh.slope_ci[1]
        f0 = linear_fit(x, y)
        hit_plain += f0.slope_ci[0] <= 0.7 <= f0.slope_ci[1]
    assert hit_hac >= 170 and hit_plain < 120


def test_linear_fit_exact_and_groups():
    x = np.linspace(0, 1, 50)
    f = linear_fit(x, 2 * x - 1)
    assert f.slope == pytest.approx(2) and f.intercept == pytest.approx(-1) and f.r2 == pytest.approx(1)
    g = np.repeat([1, 2], 25)
    assert linear_fit(x, 2 * x - 1 + 0.01 * np.sin(40 * x), groups=g, hac_lag=5).n == 50
    assert np.isnan(linear_fit(np.ones(5), np.arange(5.0)).slope)
    with pytest.raises(ValueError, match="hac_lag"):
        linear_fit(x, x, hac_lag=-1)
    with pytest.raises(ValueError, match="groups"):
        linear_fit(x, x, groups=np.ones(3))
    assert decimate_indices(10, 20).size == 10 and decimate_indices(10_000, 5000).size == 5000


def test_subsidence_fit_and_prediction():
    rng = np.random.default_rng(2)
    z = np.exp(rng.uniform(-0.5, 1.5, 4000))
    u = 0.3 * np.log(z) - 1.65 + 0.05 * rng.standard_normal(z.size)
    f = fit_subsidence(z, u, hac_lag=0)
    assert f.slope_ci[0] <= 0.3 <= f.slope_ci[1] and f.intercept_ci[0] <= -1.65 <= f.intercept_ci[1]
    assert f.rmse == pytest.approx(0.05, rel=0.1)
    pred = predict_subsidence(np.array([1.0, np.e, 0.0]), 0.3, -1.65)
    np.testing.assert_allclose(pred[:2], [-1.65, -1.35])
    assert np.isnan(pred[2])
    with pytest.raises(ValueError, match="amplitude"):
        fit_subsidence(np.array([1.0, -1.0, 2.0]), np.zeros(3))
    b, m = bin_means(np.array([0.1, 0.2, 0.3, 1.0]), np.array([1.0, 3.0, 5.0, np.nan]), 0.25)
    assert b.tolist() == [0, 1] and m.tolist() == [2.0, 5.0]


def test_unsprung_mass_and_plausibility():
    rng = np.random.default_rng(3)
    z = rng.uniform(0.5, 3, 3000)
    f = 0.3 * z + 0.005 * rng.standard_normal(z.size)
    m = fit_unsprung_mass(z, f, hac_lag=0)
    assert m.mass_ci[0] <= 300 <= m.mass_ci[1] and m.plausible
    assert not fit_unsprung_mass(z, 0.03 * z, hac_lag=0).plausible  # force channel scaled by 1/10


def test_count_actions_and_box_stats():
    x = np.array([0.5, 1.5, 2.5, 3.5])
    assert count_actions(x, np.array([0.0, 1.0, 3.0]), np.array([2.0, 1.6, 3.0])).tolist() == [1, 2, 0, 0]
    with pytest.raises(ValueError, match="start_m"):
        count_actions(x, np.array([2.0]), np.array([1.0]))
    s = box_stats(2, np.array([1.0, 2, 3, 4, 100]))
    assert (s.q1, s.median, s.q3, s.whisker_high, s.n_bins) == (2, 3, 4, 4, 5)
    rng = np.random.default_rng(4)
    n = rng.integers(0, 4, 3000)
    amp = 1 + 0.2 * n + 0.1 * rng.standard_normal(n.size)
    res = maintenance_correlation(amp, n, hac_lag=0)
    assert [g.n_actions for g in res.groups] == [0, 1, 2, 3]
    assert res.regression.slope == pytest.approx(0.2, abs=0.01) and res.regression.p_value < 1e-6


def test_superstructure_flags_a_soft_spot():
    rng = np.random.default_rng(5)
    x = (np.arange(8000) + 0.5) * 0.25  # 2 km
    sec = assign_sections(x, np.array([0.0, 1000.0]), np.array([1000.0, 2000.0]))
    amp = np.where(sec == 0, 3.0, 0.8) * np.exp(0.03 * rng.standard_normal(x.size))
    soft = (x >= 1400) & (x < 1600)
    amp[soft] *= 0.5
    flags = flag_segments(x, amp, sec, ["slab", "b91_pads"], segment_m=100)
    flagged = [(f.start_m, f.end_m) for f in flags if f.flagged]
    assert flagged == [(1400.0, 1500.0), (1500.0, 1600.0)]
    assert {f.type for f in flags} == {"slab", "b91_pads"}


def test_speed_exponent_within_locations_beats_confounding():
    """Stiffness rising along the line while the train accelerates: the pooled fit is biased,
    the within-location fit over two runs at other speeds is not."""
    rng = np.random.default_rng(6)
    bins = np.arange(4000)
    stiff = np.exp(np.linspace(0, 0.8, bins.size))
    v1 = np.linspace(20, 40, bins.size)
    v2 = v1 * 1.4
    amp = [s * (v / 27.8) ** 1.5 * np.exp(0.02 * rng.standard_normal(bins.size)) for s, v in ((stiff, v1), (stiff, v2))]
    one = fit_speed_exponent(amp[0], v1, bins, reference_speed_mps=27.8)
    both = fit_speed_exponent(np.r_[amp[0], amp[1]], np.r_[v1, v2], np.r_[bins, bins], reference_speed_mps=27.8)
    assert one.method == "pooled" and abs(one.exponent - 1.5) > 0.3
    assert both.method == "within" and both.exponent_ci[0] <= 1.5 <= both.exponent_ci[1]
    norm = normalise_amplitude(amp[1], v2, both.exponent, reference_speed_mps=27.8, min_speed_mps=30)
    assert np.isnan(norm[v2 < 30]).all()
    ok = np.isfinite(norm)
    np.testing.assert_allclose(norm[ok] / stiff[ok], 1, atol=0.1)
    flat = fit_speed_exponent(amp[0], np.full(bins.size, 30.0), bins, reference_speed_mps=27.8)
    assert flat.method == "none" and np.isnan(flat.exponent)
    # the assessment: the pooled fit is flagged, the within fit over a 1.4x speed spread is not
    assert not one.stable and "pooled_confounded" in one.unstable_reasons
    assert both.stable and both.unstable_reasons == () and both.log_speed_std > 0.1
    assert flat.unstable_reasons == ("not_estimable",)


def test_power_law_instability_flags_and_misfit():
    from app.analysis.stiffness.speed_norm import MAX_POWER_LAW_MISFIT, power_law_misfit

    rng = np.random.default_rng(2)
    bins = np.arange(3000)
    stiff = np.exp(0.1 * rng.standard_normal(bins.size))
    v1 = np.full(bins.size, 30.0)
    # a 5 % speed difference: too little spread for an exponent, and a wide interval
    v2 = v1 * 1.05
    amp = [stiff * (v / 27.8) ** 1.5 * np.exp(0.2 * rng.standard_normal(bins.size)) for v in (v1, v2)]
    near = fit_speed_exponent(np.r_[amp[0], amp[1]], np.r_[v1, v2], np.r_[bins, bins], reference_speed_mps=27.8,
                              hac_lag=100)
    assert near.method == "within" and "speed_spread_small" in near.unstable_reasons
    # a steep rise (the flank of a resonance) is outside the physical range of one exponent
    steep = [stiff * (v / 27.8) ** 5 for v in (v1, v1 * 1.5)]
    far = fit_speed_exponent(np.r_[steep[0], steep[1]], np.r_[v1, v1 * 1.5], np.r_[bins, bins], reference_speed_mps=27.8)
    assert far.exponent == pytest.approx(5, abs=0.01) and far.unstable_reasons == ("outside_physical_range",)
    assert far.with_reason("not_power_law").unstable_reasons == ("outside_physical_range", "not_power_law")
    u = np.log(np.linspace(15, 55, 30))
    assert power_law_misfit(u, 1.5 * u + 0.3, 1.5) == pytest.approx(0, abs=1e-12)
    bump = 1.5 * u + 0.8 * np.exp(-0.5 * ((u - np.log(35)) / 0.1) ** 2)
    assert power_law_misfit(u, bump, 1.5) > MAX_POWER_LAW_MISFIT
    assert np.isnan(power_law_misfit(u, bump, float("nan")))


@pytest.mark.parametrize("shift_m", [-13.4, 0.0, 7.25, 31.6])
def test_alignment_recovers_shift(shift_m):
    rng = np.random.default_rng(7)
    x = np.arange(0, 2000, 0.05)  # fine truth grid, m
    sig = np.exp(0.3 * np.interp(x, np.arange(0, 2000, 5.0), rng.standard_normal(400)))
    def run(err, seed):
        r = np.random.default_rng(seed)
        b = np.arange(400, 7600)
        pos = (b + 0.5) * 0.25 - err  # a run reporting km + err sees the truth at (reported - err)
        return b, np.interp(pos, x, sig) * np.exp(0.05 * r.standard_normal(b.size))
    rb, ra = run(0.0, 1)
    b, a = run(-shift_m, 2)
    al = align_runs(rb, ra, b, a, max_shift_m=50)
    assert al.shift_m == pytest.approx(shift_m, abs=0.5)
    assert al.confidence > 0.3 and al.overlap_m > 1500


def test_segment_table():
    b = np.arange(0, 800)  # 200 m
    runs = [(b, np.full(b.size, 1.0)), (b + 40, np.full(b.size, 2.0)), (b, np.full(b.size, 4.0))]
    t = segment_table(runs, [0.0, -10.0, 0.0], segment_m=100)
    assert t.start_m.tolist() == [0.0, 100.0]
    np.testing.assert_allclose(t.matrix, [[1, 1], [2, 2], [4, 4]])
    np.testing.assert_allclose(t.mean, [7 / 3, 7 / 3])
    np.testing.assert_allclose(t.change, [3, 3])
    np.testing.assert_allclose(t.spread, np.std([1, 2, 4], ddof=1))
    assert t.speed is None
    # with speeds: the last and the first run are compared only where they passed at similar speed
    v = [np.where(b < 400, 30.0, 30.0), np.full(b.size, 20.0), np.where(b < 400, 32.0, 40.0)]
    t = segment_table(runs, [0.0, -10.0, 0.0], segment_m=100, speeds=v, speed_tolerance=0.1)
    np.testing.assert_allclose(t.speed[[0, 2]], [[30, 30], [32, 40]])
    assert t.change[0] == 3 and np.isnan(t.change[1])


def test_segment_table_median_of_an_index_with_a_long_low_tail():
    """A stiffness index is ``ln A`` against a curve of 10 m blocks' medians: its segment value is the bins'
    median. On rough rails a bin's ``ln A`` has a long low tail (the rails' response cancelling the support's):
    the bins' mean of a typical segment reads well below 0, their median at it; a segment 20 % softer reads
    its −0.22 by the median."""
    rng = np.random.default_rng(33)
    b = np.arange(0, 800)  # two 100 m segments
    support = np.where(b < 400, 0.0, np.log(0.8))
    # |S + R| of a support phasor 1 and a rail phasor of random phase, |R| ~ 0.6: ln|S + R| − its median
    rail = 0.6 * rng.rayleigh(1.0, b.size) * np.exp(2j * np.pi * rng.random(b.size))
    ln_a = np.log(np.abs(1.0 + rail))
    ln_a -= np.median(ln_a)
    index = support + ln_a
    mean = segment_table([(b, index)], [0.0], segment_m=100)
    median = segment_table([(b, index)], [0.0], segment_m=100, statistic="median")
    assert mean.matrix[0, 0] < -0.05  # the long low tail
    assert abs(median.matrix[0, 0]) < 0.05 and median.matrix[0, 1] == pytest.approx(np.log(0.8), abs=0.06)
    exact = segment_table([(np.array([0, 1, 2, 8, 9, 10, 11]), np.array([3.0, 1.0, 2.0, 9.0, 7.0, 1.0, 5.0]))], [0.0],
                          bin_length_m=0.25, segment_m=1.0, statistic="median")
    assert exact.start_m.tolist() == [0.0, 2.0]
    np.testing.assert_allclose(exact.matrix, [[2.0, 6.0]])
    with pytest.raises(ValueError, match="statistic"):
        segment_table([(b, index)], [0.0], segment_m=100, statistic="mode")


def test_speed_exponent_outside_the_physical_range_is_flagged():
    """A pooled fit over sections where the stiffer track is passed faster gives an
    exponent no track has: it is flagged with the reason, a plausible one is not."""
    from app.analysis.stiffness.speed_norm import PHYSICAL_EXPONENT_RANGE, fit_speed_exponent

    rng = np.random.default_rng(3)
    v = np.repeat([20.0, 30.0, 45.0], 400)
    loc = np.arange(v.size)  # every location passed once: pooled
    confounded = (v / 27.8) ** 9.0 * np.exp(rng.normal(0, 0.05, v.size))
    fit = fit_speed_exponent(confounded, v, loc, reference_speed_mps=27.8, min_speed_mps=5.0)
    assert fit.method == "pooled" and fit.exponent > PHYSICAL_EXPONENT_RANGE[1]
    assert not fit.plausible and "outside the physical range" in fit.warning and "pooled" in fit.warning
    normal = (v / 27.8) ** 1.5 * np.exp(rng.normal(0, 0.05, v.size))
    fit = fit_speed_exponent(normal, v, loc, reference_speed_mps=27.8, min_speed_mps=5.0)
    assert fit.plausible and "outside the physical range" not in fit.warning
    assert fit.unstable_reasons == ("pooled_confounded",) and "pooled" in fit.warning


def test_group_median_is_each_groups_median_of_its_finite_values():
    """The reference curves' group median (one integer sort key) against numpy's median group by group:
    ties, NaN and inf values left out, groups without any value NaN, a single-value group."""
    from app.analysis.stiffness.reference_curve.smoother import group_median

    rng = np.random.default_rng(5)
    groups = rng.integers(0, 40, 3000)
    values = np.round(rng.normal(size=3000), 1)  # many ties
    values[rng.random(3000) < 0.1] = np.nan
    values[groups == 7] = np.inf
    groups[0], values[0] = 45, 2.5  # a group of one
    got = group_median(values, groups, 50)
    for g in range(50):
        v = values[(groups == g) & np.isfinite(values)]
        assert (np.isnan(got[g]) if v.size == 0 else got[g] == np.median(v)), g
    assert np.all(np.isnan(group_median(np.full(4, np.nan), np.arange(4), 4)))


def test_curve_components_join_speed_ranges_a_location_links():
    """Speed ranges of a curve separated by a gap are one component where a location has passes in both,
    separate otherwise; NaN nodes and samples beside them are in none."""
    from app.analysis.stiffness.reference_curve.curves import _components

    nodes = np.arange(10.0)
    g = np.array([0, 0, 0, np.nan, 0, 0, np.nan, np.nan, 0, 0])  # ranges [0-2], [4-5], [8-9]
    u = np.array([0.5, 1.0, 4.5, 8.5, 9.0, 6.5])
    loc = np.array([0, 1, 1, 2, 3, 4])  # location 1 links the first two ranges; the third stands alone
    node_comp, sample_comp = _components(g, u, loc, nodes)
    assert node_comp.tolist() == [0, 0, 0, -1, 0, 0, -1, -1, 4, 4]
    assert sample_comp.tolist() == [0, 0, 0, 4, 4, -1]


def test_a_prepared_local_fit_gives_the_local_fit_of_every_value_set():
    """The backfitting's smoother prepared once on the speeds (LocalFit) answers each residual set exactly as
    local_fit does, also where values are missing (NaN speeds and values left out), and recovers a curve."""
    from app.analysis.stiffness.reference_curve.smoother import LocalFit, local_fit

    rng = np.random.default_rng(3)
    u = np.log(rng.uniform(20.0, 45.0, 4000))
    u[:5] = np.nan
    nodes = np.arange(2.9, 3.9, 0.05)
    prepared = LocalFit(u, nodes, 0.1, 20)
    for k in range(3):
        r = 0.8 * (u - 3.4) ** 2 - 0.3 * u + rng.normal(0.0, 0.05, u.size)
        if k == 2:
            r[rng.random(u.size) < 0.2] = np.nan
        got, support = prepared.fit(r)
        want, want_support = local_fit(u, r, nodes, 0.1, 20)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(support, want_support)
    truth = 0.8 * (nodes - 3.4) ** 2 - 0.3 * nodes
    ok = np.isfinite(got)
    assert ok.sum() >= 10 and np.median(np.abs(got[ok] - truth[ok])) < 0.01  # the ends: one-sided windows
