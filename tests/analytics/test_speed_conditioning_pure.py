"""Reference curves and the stiffness index on synthetic passes with a known truth (pure numpy)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.analysis.stiffness.reference_curve import (
    ReferenceSet,
    bin_repeatability,
    block_samples,
    fit_reference_curve,
    fit_reference_from_rows,
    fit_reference_set,
)
from app.analysis.stiffness.stiffness_index import stiffness_index

BIN = 0.25


def _g(v: np.ndarray) -> np.ndarray:
    """A resonance-like speed response, ln m/s² (peak near 40 m/s; not a power law)."""
    u = np.log(v)
    return 0.2 + 1.2 * np.exp(-0.5 * ((u - np.log(40.0)) / 0.12) ** 2) + 1.5 * (u - np.log(30.0))


def _passes(speed_fns, *, length_m=6000.0, noise=0.02, gain=None, seed=0, effect=None):
    """25 cm rows of runs (speed as a function of position) over one class: ln A = g(v) + m(x) + e."""
    rng = np.random.default_rng(seed)
    x = (np.arange(int(length_m / BIN)) + 0.5) * BIN
    if effect is None:
        effect = 0.15 * np.sin(2 * np.pi * x / 900.0) + 0.05 * np.sin(2 * np.pi * x / 130.0)
    rows = {k: [] for k in ("a", "v", "x", "run", "wheel", "rail", "m")}
    for r, fn in enumerate(speed_fns):
        v = fn(x)
        for w in ("11", "12", "41", "42"):
            la = _g(v) + effect + noise * rng.standard_normal(x.size)
            if gain and w in gain:
                la = la + math.log(gain[w])
            for k, val in (("a", np.exp(la)), ("v", v), ("x", x), ("run", np.full(x.size, r)),
                           ("wheel", np.full(x.size, w, dtype=object)), ("rail", np.full(x.size, w[1], dtype=object)),
                           ("m", effect)):
                rows[k].append(val)
    return {k: np.concatenate(v) for k, v in rows.items()}


def _ramp(lo, hi, period_m):
    return lambda x: lo + (hi - lo) * 0.5 * (1 - np.cos(2 * np.pi * x / period_m))


def _fit(rows, **kw):
    return fit_reference_from_rows(rows["a"], rows["v"], rows["x"], rows["run"], rows["wheel"], rows["rail"],
                                   np.full(rows["a"].size, "", dtype=object), **kw)


def test_curve_follows_a_resonance_and_the_index_is_speed_invariant():
    # the stiff stretches (effect > 0) are passed slowly by run 0: speed and stiffness confounded
    rows = _passes([_ramp(20.0, 55.0, 1800.0), _ramp(55.0, 22.0, 2300.0)])
    ref = _fit(rows, n_boot=20)
    curve = ref.curves[""]
    assert curve.method == "within" and curve.n_runs == 2
    ok = np.isfinite(curve.log_amp)
    v = np.exp(curve.log_speed[ok])
    err = curve.log_amp[ok] - _g(v)
    assert np.abs(err).max() < 0.08, np.round(err, 3)
    assert curve.speed_range_mps[0] < 23 and curve.speed_range_mps[1] > 52
    assert np.all(curve.log_amp_low[ok] <= curve.log_amp[ok]) and np.all(curve.log_amp[ok] <= curve.log_amp_high[ok])
    idx = stiffness_index(rows["a"], rows["v"], "", ref)
    r0, r1 = rows["run"] == 0, rows["run"] == 1
    both = np.isfinite(idx.index[r0]) & np.isfinite(idx.index[r1])
    assert both.mean() > 0.8
    d = idx.index[r0][both] - idx.index[r1][both]
    assert np.median(np.abs(d)) < 0.05
    assert np.corrcoef(idx.index[r0][both], rows["m"][r0][both])[0, 1] > 0.95
    # the raw amplitudes of the two runs differ a lot at the same places
    raw = np.log(rows["a"][r0][both]) - np.log(rows["a"][r1][both])
    assert np.median(np.abs(raw)) > 5 * np.median(np.abs(d))
    assert np.all(idx.se[np.isfinite(idx.index)] > 0)


def test_one_pass_per_location_is_pooled_and_confounded():
    # one run whose speed follows the stiffness: the pooled curve absorbs part of it
    effect_fn = lambda x: 0.3 * np.sin(2 * np.pi * x / 1500.0)  # noqa: E731
    speed = lambda x: 35.0 * np.exp(0.4 * np.sin(2 * np.pi * x / 1500.0))  # noqa: E731
    rows = _passes([speed], effect=effect_fn((np.arange(24000) + 0.5) * BIN))
    curve = _fit(rows, n_boot=0).curves[""]
    assert curve.method == "pooled"
    ok = np.isfinite(curve.log_amp)
    err = curve.log_amp[ok] - _g(np.exp(curve.log_speed[ok]))
    assert np.ptp(err) > 0.3  # the curve took the stiffness for a speed effect


def test_matched_speed_rule_leaves_unsupported_speeds_without_index():
    def two_speeds(slow, fast):
        return lambda x: np.where(x < 3000, slow, fast) * (1 + 0.04 * np.sin(2 * np.pi * x / 400.0))

    rows = _passes([two_speeds(25.0, 50.0), two_speeds(27.0, 46.0)])
    ref = _fit(rows, n_boot=0)
    curve = ref.curves[""]
    lo, hi = curve.speed_range_mps
    assert 20 < lo < 26 and 48 < hi < 55
    out = stiffness_index(np.array([1.0, 1.0, 1.0, 1.0]), np.array([26.0, 36.0, 48.0, 90.0]), "", ref)
    assert np.isfinite(out.index[[0, 2]]).all() and np.isnan(out.index[[1, 3]]).all()
    assert np.isnan(stiffness_index(np.array([1.0]), np.array([26.0]), "slab", ref).index).all()


def test_index_uncertainty_combines_curve_and_bin_spread():
    rows = _passes([_ramp(25.0, 50.0, 2000.0), _ramp(48.0, 26.0, 2600.0)], noise=0.05)
    ref = _fit(rows, n_boot=30)
    curve = ref.curves[""]
    assert curve.repeatability == pytest.approx(0.05, rel=0.15)
    v = np.array([30.0, 40.0])
    lr, se_c = curve.evaluate(v)
    out = stiffness_index(np.exp(lr + 0.1), v, "", ref)
    np.testing.assert_allclose(out.index, 0.1, atol=1e-12)
    np.testing.assert_allclose(out.se, np.sqrt(se_c**2 + curve.repeatability**2))
    wide = stiffness_index(np.exp(lr), v, np.array(["", ""], dtype=object), ref, log_spread=0.3)
    assert np.all(wide.se > 0.3)
    assert np.all(np.isfinite(out.z)) and curve.spread > 0


def test_round_trip_and_wheel_offsets_find_a_miscalibrated_sensor():
    rows = _passes([_ramp(25.0, 50.0, 2000.0), _ramp(48.0, 26.0, 2600.0)], gain={"41": 1.2})
    ref = _fit(rows, n_boot=10)
    again = ReferenceSet.from_dict(ref.to_dict())
    c0, c1 = ref.curves[""], again.curves[""]
    np.testing.assert_array_equal(c0.log_amp, c1.log_amp)
    assert (c0.method, c0.n_samples, c0.spread) == (c1.method, c1.n_samples, c1.spread)
    off = {o.wheel: o for o in ref.wheel_offsets}
    # rail 1 carries wheels 11 and 41: half the gain error each way
    assert off["41"].offset == pytest.approx(math.log(1.2) / 2, abs=0.02)
    assert off["41"].low > 0.03 and off["11"].high < -0.03
    assert abs(off["12"].offset) < 0.01 and abs(off["42"].offset) < 0.01
    # the rail difference is then the half of the gain error on rail 1
    assert ref.rail_difference == pytest.approx(-math.log(1.2) / 2, abs=0.02)


def test_bin_repeatability_from_pairs():
    rng = np.random.default_rng(3)
    n = 4000
    truth = rng.normal(size=n)
    y = np.concatenate([truth + 0.1 * rng.standard_normal(n), truth + 0.1 * rng.standard_normal(n)])
    u = np.full(2 * n, np.log(30.0))
    bins = np.tile(np.arange(n), 2)
    rail = np.full(2 * n, "1")
    passes = np.repeat(["a", "b"], n)
    assert bin_repeatability(y, u, rail, bins, passes) == pytest.approx(0.1, rel=0.08)
    far = u.copy()
    far[n:] += 0.5  # passes at other speeds are not pairs
    assert math.isnan(bin_repeatability(y, far, rail, bins, passes))


def test_block_samples_and_argument_checks():
    rows = _passes([_ramp(25.0, 50.0, 2000.0)])
    cls = np.where(rows["x"] < 3000, "slab", "b91_pads").astype(object)
    s = block_samples(rows["a"], rows["v"], rows["x"], rows["run"], rows["wheel"], rows["rail"], cls)
    assert len(s) == 4 * 600 and set(s.cls) == {"slab", "b91_pads"}
    assert np.unique(s.location).size == 2 * 600  # a block of one rail
    ref = fit_reference_set(s, n_boot=0)
    assert set(ref.curves) == {"slab", "b91_pads"}
    with pytest.raises(ValueError, match="speed_tolerance"):
        fit_reference_curve(s, speed_tolerance=0.0)
    with pytest.raises(ValueError, match="equal length"):
        block_samples(rows["a"][:-1], rows["v"], rows["x"], rows["run"], rows["wheel"], rows["rail"], cls)
    with pytest.raises(ValueError, match="classes"):
        stiffness_index(np.ones(3), np.ones(3), np.array(["", ""], dtype=object), ref)
    tiny = fit_reference_curve(s.take(np.arange(len(s)) < 5))
    assert tiny.method == "none" and tiny.log_amp.size == 0


def test_section_classes_leave_changes_of_superstructure_without_class():
    from app.analysis.stiffness.superstructure import section_classes

    x = np.array([35.0, 95.0, 120.0, 150.0, 185.0, 250.0, 305.0, 325.0, 420.0])
    start, end = np.array([0.0, 100.0, 200.0]), np.array([100.0, 200.0, 300.0])
    types = np.array(["slab", "b91_pads", "b91_pads"], dtype=object)
    out = section_classes(x, start, end, types, boundary_margin_m=30.0)
    # 0 m and 100 m are changes; 200 m is not (same type); 300 m ends the sections
    assert out.tolist() == ["slab", None, None, "b91_pads", "b91_pads", "b91_pads", None, None, ""]
    assert section_classes(x, start, end, types).tolist()[:3] == ["slab", "slab", "b91_pads"]
    assert section_classes(x, np.zeros(0), np.zeros(0), np.zeros(0, dtype=object), boundary_margin_m=30).tolist() == [""] * 9
    ref = fit_reference_set(block_samples(*[np.zeros(0)] * 7), n_boot=0)
    assert ref.curves == {}
    out_idx = stiffness_index(np.ones(2), np.full(2, 30.0), np.array([None, "slab"], dtype=object), ref)
    assert np.isnan(out_idx.index).all()
