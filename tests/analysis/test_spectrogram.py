"""Spectrograms of a window: PSD scaling, order extraction against a known signal, the
pipeline's bandwidth rule, argument checks."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.orders import railway_multipliers
from app.analysis.recipe import STEP_WIDTH_FACTOR, order_recipe
from app.analysis.settings import ProcessingSettings
from app.analysis.spectrogram import (
    component_padding,
    extract_components,
    psd_spectrogram,
    window_spectrograms,
)


def test_psd_of_a_tone_peaks_at_its_frequency_and_integrates_to_its_power():
    fs, f0, amp = 10_000.0, 73.0, 2.0
    t = np.arange(int(20 * fs)) / fs
    spec = psd_spectrogram(amp * np.cos(2 * np.pi * f0 * t), fs, f_max=200.0, resolution_hz=1.0)
    assert spec.freq_hz[-1] <= 200.0 and spec.psd.shape == (spec.freq_hz.size, spec.time_s.size)
    df = spec.freq_hz[1] - spec.freq_hz[0]
    assert df <= 1.05
    peak = spec.freq_hz[np.argmax(spec.psd.mean(axis=1))]
    assert abs(peak - f0) <= df
    power = spec.psd.sum(axis=0) * df  # Parseval: A²/2 per frame
    np.testing.assert_allclose(power, amp**2 / 2, rtol=0.02)
    assert spec.time_s[0] > 0 and spec.time_s[-1] < t[-1]  # full frames only


def _railway_signal(fs=5000.0, seconds=30.0, seed=0):
    """Sleeper passage + 11 wheel orders at a speed ramp 20 -> 30 m/s, white noise."""
    rng = np.random.default_rng(seed)
    n = int(seconds * fs)
    v = np.linspace(20.0, 30.0, n)
    mult = railway_multipliers(0.92, 0.6, 11)
    phase = 2 * np.pi * np.multiply.outer(mult, np.cumsum(v) / fs)
    amps = np.r_[1.5, 0.8 / np.arange(1, 12)]
    clean = (amps[:, None] * np.cos(phase + 0.3)).sum(axis=0)
    return v, clean, clean + rng.normal(0.0, 1.0, n)


def test_extracted_components_follow_the_true_harmonic_sum():
    fs = 5000.0
    v, clean, y = _railway_signal(fs)
    settings = ProcessingSettings()
    out = extract_components(y, fs, v, wheel_diameter=0.92, sleeper_spacing=0.6, settings=settings)
    inner = slice(int(5 * fs), int(25 * fs))  # away from the ends where the filter settles
    err = np.sqrt(np.mean((out[inner] - clean[inner]) ** 2)) / np.sqrt(np.mean(clean[inner] ** 2))
    assert err < 0.1, f"relative rms error {err:.3f}"
    # evaluated at a reduced rate: the same values
    idx = np.arange(0, y.size, 7)
    sub = extract_components(y, fs, v, wheel_diameter=0.92, sleeper_spacing=0.6, settings=settings, out_index=idx)
    np.testing.assert_allclose(sub, out[idx], atol=1e-9)


def test_window_spectrograms_put_the_components_on_the_order_lines():
    fs = 5000.0
    v, _, y = _railway_signal(fs, seconds=40.0, seed=1)
    settings = ProcessingSettings()
    pad = component_padding(fs, v, 0.92, 0.6, settings)
    assert pad > 0
    lo, hi = int(10 * fs), int(30 * fs)
    w = window_spectrograms(y, fs, v, core=(lo, hi), wheel_diameter=0.92, sleeper_spacing=0.6, settings=settings)
    assert w.raw_db.shape == w.components_db.shape == (w.freq_hz.size, w.time_s.size)
    recipe = order_recipe(0.92, 0.6, settings)
    assert w.order_labels[0] == "sleeper" and tuple(w.order_labels) == recipe.labels  # f_s, 2f_s, 3f_s, 1..11
    # order tracks: multiplier × frame speed, speed as generated
    t_abs = (lo + w.frame_index) / fs
    v_true = np.interp(t_abs, np.arange(v.size) / fs, v)
    np.testing.assert_allclose(w.speed, v_true, rtol=0.01)
    np.testing.assert_allclose(w.order_freq_hz, np.multiply.outer(recipe.multipliers, w.speed))
    # the components' power lies on the order lines; the raw signal also has broadband noise
    df = w.resolution_hz
    near = np.zeros_like(w.components_db, dtype=bool)
    for j in range(w.time_s.size):
        for f in w.order_freq_hz[:, j]:
            near[:, j] |= np.abs(w.freq_hz - f) <= 2.5 * df
    comp = 10 ** (w.components_db / 10)
    assert comp[near].sum() / comp.sum() > 0.97
    # between the lines the components are far below the raw signal's noise floor
    assert np.median(w.raw_db[~near]) - np.median(w.components_db[~near]) > 20.0


def test_order_bandwidth_is_the_pipelines_rule():
    from app.analysis.recipe import order_recipe

    for kw in ({}, {"bandwidth_orders": 0.25, "min_speed_kmh": 40.0}, {"min_speed_kmh": 0.0}):
        s = ProcessingSettings(**kw)
        for d_w in (0.86, 0.92):
            recipe = order_recipe(d_w, 0.6, s)
            wheel = s.bandwidth_orders / (np.pi * d_w)
            track = STEP_WIDTH_FACTOR[s.filter_order] / s.track_resolution_m  # c_q / resolution
            per_speed = np.where([x.isdigit() for x in recipe.labels], wheel, track)
            floor = per_speed * max(s.min_speed_kmh / 3.6, 1.0)
            assert recipe.bandwidth_per_speed == pytest.approx(per_speed, rel=1e-12)
            assert recipe.bandwidth_floor == pytest.approx(floor, rel=1e-12)
    with pytest.raises(ValueError, match="wheel_diameter"):
        order_recipe(0.0, 0.6, ProcessingSettings())


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"fs": 0.0}, "fs"),
        ({"f_max": 6000.0}, "f_max"),
        ({"resolution_hz": -1.0}, "resolution_hz"),
        ({"y": np.zeros(8)}, "y"),
        ({"y": np.r_[np.zeros(100), np.nan]}, "NaN"),
    ],
)
def test_psd_spectrogram_checks_its_arguments(kwargs, match):
    args = {"y": np.zeros(1000), "fs": 10_000.0, "f_max": 100.0, "resolution_hz": 1.0} | kwargs
    y = args.pop("y")
    fs = args.pop("fs")
    with pytest.raises(ValueError, match=match):
        psd_spectrogram(y, fs, **args)


def test_window_spectrograms_rejects_a_standing_train():
    fs = 2000.0
    y = np.zeros(20_000)
    v = np.full(20_000, 1.0)  # 3.6 km/h < min_speed_kmh
    with pytest.raises(ValueError, match="speed"):
        window_spectrograms(y, fs, v, core=(5000, 15000), wheel_diameter=0.92, sleeper_spacing=0.6,
                            settings=ProcessingSettings())
