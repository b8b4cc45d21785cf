"""Accuracy of the engine against signals with known truth (default decimation and chunking)."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.orders import sleeper_passage, wheel_orders
from app.analysis.vkf import VKFWarning, vkf
from app.simulate.signals import paper_signal, phase_from_freqs, railway_signal


def _wrap(angle: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * angle))


def _rel_rms(estimate: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean((estimate - truth) ** 2) / np.mean(truth**2)))


# ---------------------------------------------------------------- exactness on pure tones


@pytest.mark.parametrize("f0", [500.0, 73.3, 1234.5])
def test_unit_tone_at_paper_settings(f0):
    """Issue: "a pure unit tone comes back at 1 +- 0.001 at the paper's settings"."""
    fs, bandwidth, q, duration, edge = 12000.0, 1.5, 2, 10.0, 2.0
    n = int(duration * fs)
    freqs = np.full(n, f0)
    y = np.cos(phase_from_freqs(freqs, fs) + 0.7)
    res = vkf(y, fs, freqs[None, :], bandwidth, q)
    inner = slice(int(edge * fs), n - int(edge * fs))
    amp_err = np.abs(res.amplitude[0, inner] - 1.0).max()
    assert amp_err <= 1e-3, f"max |amplitude - 1| = {amp_err:.2e}"
    phase_err = np.abs(_wrap(res.phase[0, inner] - 0.7)).max()
    assert phase_err <= 1e-3, f"max phase error {phase_err:.2e} rad"


def test_unit_chirp_at_paper_settings():
    """A tone of time-varying frequency, given its frequency, is recovered exactly too."""
    fs, bandwidth, q, duration, edge = 12000.0, 1.5, 2, 12.0, 2.0
    n = int(duration * fs)
    t = np.arange(n) / fs
    freqs = 300 + 100 * np.sin(2 * np.pi * 0.05 * t) + 10 * t
    y = np.cos(phase_from_freqs(freqs, fs) - 2.0)
    res = vkf(y, fs, freqs[None, :], bandwidth, q)
    inner = slice(int(edge * fs), n - int(edge * fs))
    assert np.abs(res.amplitude[0, inner] - 1.0).max() <= 1e-3
    assert np.abs(_wrap(res.phase[0, inner] + 2.0)).max() <= 1e-3


@pytest.mark.parametrize("f0", [211.4, 555.5])
def test_q3_narrow_band_at_24khz(f0):
    """Issue: "q = 3 works at 0.5 Hz / 24 kHz" (amplitude within 1e-3 in the interior)."""
    fs, bandwidth, q, duration, edge = 24000.0, 0.5, 3, 20.0, 6.0
    n = int(duration * fs)
    freqs = np.full((1, n), f0)
    y = 1.0 * np.cos(phase_from_freqs(freqs, fs)[0] + 0.2)
    res = vkf(y, fs, freqs, bandwidth, q)
    inner = slice(int(edge * fs), n - int(edge * fs))
    assert np.all(np.isfinite(res.amplitude))
    amp_err = np.abs(res.amplitude[0, inner] - 1.0).max()
    assert amp_err <= 1e-3, f"max |amplitude - 1| = {amp_err:.2e}"


# ---------------------------------------------------------------- the paper's validation signal


@pytest.fixture(scope="module")
def paper_run():
    sig = paper_signal()  # 60 s at 12 kHz, noise 0.75
    with pytest.warns(VKFWarning):  # f1 crosses f3
        res = vkf(sig.y, sig.fs, sig.freqs, 1.5, 2)
    return sig, res


def test_paper_signal_waveforms(paper_run):
    """Issue: each extracted waveform within 2 % relative RMS of the truth, 1 s off each end."""
    sig, res = paper_run
    inner = slice(int(sig.fs), sig.n_samples - int(sig.fs))
    errors = [_rel_rms(res.waveform[k, inner], sig.waveforms[k, inner]) for k in range(3)]
    assert max(errors) <= 0.02, f"relative RMS waveform errors {np.round(errors, 4)}"


def test_paper_signal_amplitudes(paper_run):
    sig, res = paper_run
    inner = slice(int(sig.fs), sig.n_samples - int(sig.fs))
    errors = [_rel_rms(res.amplitude[k, inner], sig.amplitude[k, inner]) for k in range(3)]
    assert max(errors) <= 0.02, f"relative RMS amplitude errors {np.round(errors, 4)}"
    assert res.valid.all()
    # the residual is the noise (plus what the filters let through)
    assert np.std(res.residual[inner]) == pytest.approx(0.75, rel=0.02)


def test_paper_signal_crossing_is_reported(paper_run):
    """f1 dips through f3 = 500 Hz four times in 60 s: orders 0 and 2 come closer than 1.5 Hz."""
    _, res = paper_run
    pairs = {tuple(sorted(p)) for p in res.close_orders}
    assert pairs == {(0, 2)}


# ---------------------------------------------------------------- railway orders


@pytest.fixture(scope="module")
def railway_run():
    sig = railway_signal(duration=60.0, fs=5000.0, noise_std=1.0, seed=11)
    f1 = sig.freqs[1]
    bandwidth = np.broadcast_to(0.1 * f1, sig.freqs.shape)  # constant 0.1 wheel orders
    res = vkf(sig.y, sig.fs, sig.freqs, bandwidth, 2)
    return sig, res


def test_engine_orders_match_the_simulated_orders(railway_run):
    sig, _ = railway_run
    np.testing.assert_allclose(wheel_orders(sig.speed, 0.92, 11), sig.freqs[1:], rtol=1e-12)
    np.testing.assert_allclose(sleeper_passage(sig.speed, 0.6), sig.freqs[0], rtol=1e-12)
    stack = np.vstack([sleeper_passage(sig.speed, 0.6), wheel_orders(sig.speed, 0.92)])
    np.testing.assert_allclose(stack, sig.freqs, rtol=1e-12)


def test_railway_sleeper_amplitude(railway_run):
    """Issue: sleeper-order amplitude within 5 % RMS in the interior (40-200 km/h)."""
    sig, res = railway_run
    inner = slice(5 * int(sig.fs), sig.n_samples - 5 * int(sig.fs))
    err = _rel_rms(res.amplitude[0, inner], sig.amplitude[0, inner])
    assert err <= 0.05, f"sleeper amplitude relative RMS error {err:.4f}"
    assert res.valid[:, inner].all()
    # the pair sleeper / wheel order 5 is 0.18 orders apart, bandwidth 0.1 orders: not close
    assert res.close_orders == []


def test_railway_strong_wheel_orders(railway_run):
    """Wheel orders 5 (next to the sleeper order) and 9, where they are well above the noise."""
    sig, res = railway_run
    fast = sig.speed * 3.6 >= 120.0
    for order in (5, 9):
        err = _rel_rms(res.amplitude[order, fast], sig.amplitude[order, fast])
        assert err <= 0.05, f"wheel order {order}: relative RMS amplitude error {err:.4f}"
        phase_err = np.sqrt(np.mean(_wrap(res.phase[order, fast] - sig.phase[order, fast]) ** 2))
        assert phase_err <= 0.05, f"wheel order {order}: RMS phase error {phase_err:.4f} rad"
