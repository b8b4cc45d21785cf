"""The railway order recipe: orders and labels, bandwidth rule and floor, the phase
convention (envelope phases referred to a start position), the overlap of several
wheels, per-order bandwidths, argument checks."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from app.analysis.orders import railway_multipliers
from app.analysis.recipe import (
    CHUNK_JOIN_TOL,
    SLEEPER,
    STEP_WIDTH_FACTOR,
    OrderRecipe,
    in_band_wheel_orders,
    order_collisions,
    order_overlap,
    order_recipe,
    track_bandwidth_per_speed,
    travel_phase,
    wheel_recipe,
)
from app.analysis.settings import LEGACY_VALUES, ProcessingSettings
from app.analysis.vkf import vkf_overlap

#: the recipe before issue 15: the sleeper order alone, as narrow as the wheel orders
LEGACY = dict(LEGACY_VALUES)


def test_orders_labels_and_rows():
    settings = ProcessingSettings(n_wheel_orders=5, **LEGACY)
    r = order_recipe(0.91, 0.65, settings)
    assert r.labels == (SLEEPER, "1", "2", "3", "4", "5")
    np.testing.assert_array_equal(r.multipliers, railway_multipliers(0.91, 0.65, 5))
    assert r.sleeper_row == 0
    np.testing.assert_array_equal(r.wheel_orders, np.arange(1, 6))
    np.testing.assert_array_equal(r.wheel_rows, np.arange(1, 6))
    assert r.filter_order == settings.filter_order and r.min_speed == pytest.approx(25.0 / 3.6)
    assert (r.wheel_diameter, r.sleeper_spacing) == (0.91, 0.65)
    with pytest.raises(ValueError):
        r.multipliers[0] = 1.0  # the recipe's arrays are read-only


def test_bandwidth_rule_and_floor():
    settings = ProcessingSettings(bandwidth_orders=0.2, min_speed_kmh=36.0, **LEGACY)
    r = order_recipe(0.92, 0.6, settings)
    per_speed = 0.2 / (np.pi * 0.92)
    np.testing.assert_allclose(r.bandwidth_per_speed, per_speed, rtol=1e-15)
    assert r.floor_speed == pytest.approx(10.0)
    np.testing.assert_allclose(r.bandwidth_floor, per_speed * 10.0, rtol=1e-15)
    v = np.array([0.0, 5.0, 10.0, 20.0, 44.4])
    np.testing.assert_array_equal(np.asarray(r.bandwidths(v)),
                                  np.maximum(np.multiply.outer(r.bandwidth_per_speed, v), r.bandwidth_floor[:, None]))
    np.testing.assert_array_equal(np.asarray(r.frequencies(v)), np.multiply.outer(r.multipliers, v))
    assert r.bandwidth_range(5.0, 20.0) == pytest.approx((per_speed * 10.0, per_speed * 20.0), rel=1e-15)
    # a standing train still gets a finite filter: floor at 1 m/s when min_speed_kmh is 0
    assert order_recipe(0.92, 0.6, ProcessingSettings(min_speed_kmh=0.0)).floor_speed == 1.0


@pytest.mark.parametrize("start_m", [0.0, 1234.5])
def test_envelope_phases_follow_the_phase_convention(start_m):
    """Orders with phases φ_n at the start position come out as envelopes a_n·exp(iφ_n)."""
    fs = 4000.0
    n = int(20 * fs)
    v = np.linspace(25.0, 30.0, n)
    r = order_recipe(0.92, 0.6, ProcessingSettings(n_wheel_orders=3, **LEGACY))
    amps = np.array([1.0, 0.5, 0.3, 0.2])
    phis = np.array([0.4, -1.1, 2.0, 0.9])
    psi = travel_phase(v, fs, start_m)
    np.testing.assert_allclose(psi, 2 * np.pi * (start_m + np.cumsum(v) / fs))
    y = (amps[:, None] * np.cos(r.order_phases(psi) + phis[:, None])).sum(axis=0)
    env = r.solve(y, fs, v, start_m).envelope_at(np.arange(n // 4, 3 * n // 4, 1000))
    np.testing.assert_allclose(np.abs(env), amps[:, None] * np.ones(env.shape), rtol=0.02)
    np.testing.assert_allclose(np.angle(env * np.exp(-1j * phis[:, None])), 0.0, atol=0.03)


def test_overlap_of_several_wheels_covers_the_highest_order_and_the_narrowest_filter():
    settings = ProcessingSettings()
    small, large = order_recipe(0.86, 0.6, settings), order_recipe(0.95, 0.6, settings)
    fs, v = 10_000.0, np.array([-30.0, 22.0, 41.0])  # the speed's absolute value counts
    f_max = float(small.multipliers.max()) * 41.0
    bw_min, bw_max = large.bandwidth_range(22.0, 41.0)
    expect = vkf_overlap(fs, 0.0, f_max, bw_min, bw_max, settings.filter_order, tol=CHUNK_JOIN_TOL)
    assert order_overlap(fs, v, [small, large], tol=CHUNK_JOIN_TOL) == expect
    assert order_overlap(fs, v, [large, small], tol=CHUNK_JOIN_TOL) == expect
    # one wheel, the engine's own tolerance: longer than the chunk seams'
    one = order_overlap(fs, v, [small])
    assert one == vkf_overlap(fs, 0.0, f_max, *small.bandwidth_range(22.0, 41.0), settings.filter_order)
    assert one > order_overlap(fs, v, [small], tol=CHUNK_JOIN_TOL)
    with pytest.raises(ValueError, match="recipes"):
        order_overlap(fs, v, [])
    with pytest.raises(ValueError, match="speed"):
        order_overlap(fs, np.zeros(0), [small])


def test_per_order_bandwidths_reach_the_filter():
    """A recipe with its own bandwidth per order (what a later recipe may do) is
    solved with those bandwidths: a wider sleeper filter, narrow wheel orders."""
    base = order_recipe(0.92, 0.6, ProcessingSettings(n_wheel_orders=2, **LEGACY))
    wide = dataclasses.replace(base, bandwidth_per_speed=base.bandwidth_per_speed * np.array([4.0, 1.0, 1.0]))
    v = np.full(8, 20.0)
    np.testing.assert_allclose(np.asarray(wide.bandwidths(v))[:, 0], base.bandwidth_per_speed * [80.0, 20.0, 20.0])
    assert wide.bandwidth_range(20.0, 20.0) == pytest.approx(
        (base.bandwidth_per_speed[1] * 20.0, base.bandwidth_per_speed[0] * 80.0)
    )
    fs = 2000.0
    t = np.arange(int(10 * fs)) / fs
    y = np.cos(2 * np.pi * (base.multipliers[0] * 20.0 + 1.0) * t)  # 1 Hz beside the sleeper order
    env_base = np.abs(base.solve(y, fs, np.full(t.size, 20.0)).envelope_at(np.arange(5000, 15000, 500)))
    env_wide = np.abs(wide.solve(y, fs, np.full(t.size, 20.0)).envelope_at(np.arange(5000, 15000, 500)))
    assert env_wide[0].mean() > 2 * env_base[0].mean()  # the wide filter passes the neighbour


def test_wheel_recipe_reads_the_metadata():
    meta = SimpleNamespace(wheel_diameters={"11": 0.9, "41": 0.88}, sleeper_spacing=0.65)
    r = wheel_recipe(meta, "41", ProcessingSettings())
    assert (r.wheel_diameter, r.sleeper_spacing) == (0.88, 0.65)
    with pytest.raises(KeyError):
        wheel_recipe(meta, "12", ProcessingSettings())


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"labels": ("1", "2", "3")}, "sleeper"),
        ({"multipliers": np.ones(2)}, "multipliers"),
        ({"bandwidth_per_speed": np.array([0.1, 0.0, 0.1])}, "bandwidth_per_speed"),
        ({"floor_speed": 0.0}, "floor_speed"),
    ],
)
def test_recipe_checks_its_arguments(change, match):
    base = order_recipe(0.92, 0.6, ProcessingSettings(n_wheel_orders=2, **LEGACY))
    with pytest.raises(ValueError, match=match):
        dataclasses.replace(base, **change)
    with pytest.raises(ValueError, match="sleeper_spacing"):
        order_recipe(0.92, -0.6, ProcessingSettings())
    assert isinstance(base, OrderRecipe)


def test_default_recipe_tracks_sleeper_harmonics_wide_and_wheel_orders_narrow():
    settings = ProcessingSettings()
    r = order_recipe(0.92, 0.6, settings)
    assert r.labels == (SLEEPER, "sleeper_2", "sleeper_3", *[str(lvl) for lvl in range(1, 12)])
    assert r.harmonics == {1: 0, 2: 1, 3: 2} and list(r.track_rows) == [0, 1, 2]
    np.testing.assert_array_equal(r.powers, [1, 2, 3, *range(1, 12)])
    np.testing.assert_allclose(r.multipliers[:3], np.array([1, 2, 3]) / 0.6)
    np.testing.assert_allclose(r.multipliers[3:], railway_multipliers(0.92, 0.6, 11)[1:])
    track = STEP_WIDTH_FACTOR[settings.filter_order] / settings.track_resolution_m
    np.testing.assert_allclose(r.bandwidth_per_speed[:3], track)
    np.testing.assert_allclose(r.bandwidth_per_speed[3:], settings.bandwidth_orders / (np.pi * 0.92))
    assert r.notes == ()
    assert track_bandwidth_per_speed(6.0, 1) == pytest.approx(2 * np.log(5) / np.pi * np.sqrt(np.sqrt(2) - 1) / 6.0)


def test_stored_settings_without_the_new_keys_mean_the_old_recipe():
    old = ProcessingSettings.from_stored({"bandwidth_orders": 0.1, "n_wheel_orders": 11})
    assert (old.track_resolution_m, old.sleeper_harmonics, old.force_mean_window_m) == (None, 1, 0.0)
    r = order_recipe(0.92, 0.6, old)
    assert r.labels == (SLEEPER, *[str(lvl) for lvl in range(1, 12)])
    np.testing.assert_allclose(r.bandwidth_per_speed, 0.1 / (np.pi * 0.92))
    # a new request without them gets today's defaults
    assert ProcessingSettings.from_dict({}) == ProcessingSettings()
    assert ProcessingSettings.from_stored(ProcessingSettings().to_dict()) == ProcessingSettings()


def test_harmonic_on_a_wheel_order_is_dropped_and_said():
    """d_w = 0.86 m: f_s at 4.50 wheel orders, 2·f_s at 9.006 — inside wheel order 9's band."""
    r = order_recipe(0.86, 0.6, ProcessingSettings())
    assert "sleeper_2" not in r.labels and "sleeper_3" in r.labels and "9" in r.labels
    assert r.harmonics == {1: 0, 3: 1}
    assert len(r.notes) == 1 and "2·f_s" in r.notes[0] and "wheel order 9" in r.notes[0]


def test_fundamental_on_a_wheel_order_drops_the_wheel_order():
    d_w = 5 * 0.6 / np.pi  # f_s exactly at wheel order 5
    r = order_recipe(d_w, 0.6, ProcessingSettings())
    assert "5" not in r.labels and SLEEPER in r.labels
    assert 5 not in r.wheel_orders and any("wheel order 5 is not extracted" in n for n in r.notes)


@pytest.mark.parametrize("settings, d_w, expect", [
    (ProcessingSettings(), 0.92, ["5", "9", "10"]),  # 0.18 from f_s; 0.63 and 0.37 from 2·f_s (band 0.69 orders)
    (ProcessingSettings(n_wheel_orders=20), 0.92, ["5", "9", "10", "14", "15"]),  # 3·f_s at 14.45 orders
    (ProcessingSettings(track_resolution_m=20.0), 0.92, []),  # a 0.10-order track band holds no wheel order
    (ProcessingSettings(**LEGACY), 0.92, []),  # every order 0.1 orders wide
    (ProcessingSettings(n_wheel_orders=4), 0.92, []),
])
def test_wheel_orders_inside_a_track_band_are_stationary(settings, d_w, expect):
    """Issue 26: a wheel order inside a track order's band is solved as a stationary order (a function of
    speed), so that it does not take the track order's changes at its line."""
    r = order_recipe(d_w, 0.6, settings)
    rows = in_band_wheel_orders(r.labels, r.multipliers, r.bandwidth_per_speed)
    assert [r.labels[i] for i in rows] == expect
    assert list(np.flatnonzero(r.stationary)) == list(rows)


def test_order_collisions_rule():
    labels = (SLEEPER, "sleeper_2", "1", "2")
    mult = np.array([1.0, 2.0, 1.05, 2.5])
    bw = np.array([0.5, 0.5, 0.1, 0.1])
    dropped, notes = order_collisions(labels, mult, bw)
    assert dropped == {"1"} and len(notes) == 1  # 0.05 apart, inside the narrower (0.1) band
    mult = np.array([1.0, 2.0, 1.2, 2.05])
    dropped, notes = order_collisions(labels, mult, bw)
    assert dropped == {"sleeper_2"} and "2·f_s" in notes[0]  # 1.2 is 0.2 away: no collision


@pytest.mark.parametrize("q", [1, 2, 3])
def test_track_resolution_is_the_measured_step_width(q):
    """A sleeper order whose amplitude steps 1 → 2 at x = 60 m: with track_resolution_m = 5 the VKF's
    amplitude rises from 10 % to 90 % of the step over 5 m (the c_q of STEP_WIDTH_FACTOR), the
    50 % point on the step, overshoot as derived (q = 2: 3.4 %)."""
    from scipy.integrate import quad

    # c_q from the filter response itself: s(t) = 1/2 + (1/π)∫ H(f) sin(2πft)/f df, B = 1 Hz,
    # H = 1/(1 + (√2−1)(2f)^(2q)) (|H| = 1/√2 at ±B/2)
    k = np.sqrt(2.0) - 1.0

    def s_of(t):
        def integrand(f):
            return np.sin(2 * np.pi * f * t) / f / (1 + k * (2 * f) ** (2 * q))

        return 0.5 + quad(integrand, 0, 80, limit=800)[0] / np.pi

    lo, hi = 0.0, 2.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if s_of(mid) < 0.9 else (lo, mid)
    assert 2 * lo == pytest.approx(STEP_WIDTH_FACTOR[q], rel=2e-3)

    fs, v = 2000.0, 30.0
    n = int(120.0 / v * fs)
    x = np.arange(n) * v / fs
    amp = np.where(x < 60.0, 1.0, 2.0)
    y = amp * np.cos(2 * np.pi * x / 0.6 + 0.4)
    settings = ProcessingSettings(track_resolution_m=5.0, filter_order=q, sleeper_harmonics=1, n_wheel_orders=1)
    r = order_recipe(0.92, 0.6, settings)
    a = np.abs(r.solve(y, fs, np.full(n, v)).envelope_at(np.arange(n))[r.sleeper_row])
    s = (a - 1.0) / 1.0
    rise = (x > 50) & (x < 70)
    i90 = int(np.argmax(s[rise] >= 0.9))
    xs, ss = x[rise][: i90 + 1], s[rise][: i90 + 1]
    i10 = int(np.flatnonzero(ss < 0.1)[-1])
    x10, x50, x90 = (np.interp(level, ss[i10:], xs[i10:]) for level in (0.1, 0.5, 0.9))
    overshoot = s[(x > 60) & (x < 80)].max() - 1.0
    assert x90 - x10 == pytest.approx(5.0, rel=0.03)
    assert x50 == pytest.approx(60.0, abs=0.1)
    assert overshoot == pytest.approx({1: 0.0, 2: 0.0335, 3: 0.056}[q], abs=0.01)
