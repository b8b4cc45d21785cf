"""The synthetic signals are right on their own (no engine involved)."""

from __future__ import annotations

import numpy as np
import pytest

from app.simulate.signals import (
    DEFAULT_OOR_RADIUS_UM,
    paper_signal,
    phase_from_freqs,
    railway_signal,
)
from tests.vkf.reference_vkf import carrier_phase

# ---------------------------------------------------------------- paper signal (Eqs. 21-23)


@pytest.fixture(scope="module")
def paper():
    return paper_signal()


def test_paper_signal_shapes_and_defaults(paper):
    n = 60 * 12000
    assert paper.fs == 12000.0
    assert paper.y.shape == (n,)
    for name in ("freqs", "phi", "amplitude", "phase", "waveforms"):
        assert getattr(paper, name).shape == (3, n), name
    assert paper.speed is None
    assert paper.noise_std == 0.75
    np.testing.assert_allclose(paper.t, np.arange(n) / 12000.0)


def test_paper_signal_follows_eq23(paper):
    t = paper.t
    np.testing.assert_allclose(paper.amplitude[0], 0.02 * t + 1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        paper.amplitude[1],
        1 + 0.5 * np.sin(2 * np.pi * 0.02 * t) * np.cos(2 * np.pi * 0.04 * t),
        atol=1e-12,
    )
    np.testing.assert_array_equal(paper.amplitude[2], 1.0)
    np.testing.assert_allclose(paper.freqs[0], 600 + 120 * np.cos(2 * np.pi * 0.03 * t), atol=1e-9)
    np.testing.assert_allclose(paper.freqs[1], 240 - 120 * np.cos(2 * np.pi * 0.01 * t), atol=1e-9)
    np.testing.assert_array_equal(paper.freqs[2], 500.0)
    np.testing.assert_allclose(paper.phase[0], 0.06 * t - 2, atol=1e-12)
    np.testing.assert_array_equal(paper.phase[1], 0.0)
    np.testing.assert_array_equal(paper.phase[2], -1.0)
    # a few hand-checked values: a1(25 s) = 1.5, f1(0) = 720 Hz, f2(50 s) = 360 Hz, a2(12.5 s)
    k = int(25 * 12000)
    assert paper.amplitude[0, k] == pytest.approx(1.5)
    assert paper.freqs[0, 0] == pytest.approx(720.0)
    assert paper.freqs[1, 50 * 12000] == pytest.approx(360.0)
    k = int(12.5 * 12000)
    expected = 1 + 0.5 * np.sin(2 * np.pi * 0.25) * np.cos(2 * np.pi * 0.5)
    assert paper.amplitude[1, k] == pytest.approx(expected)


def test_paper_signal_components_are_exact(paper):
    np.testing.assert_array_equal(
        paper.waveforms, paper.amplitude * np.cos(paper.phi + paper.phase)
    )
    np.testing.assert_allclose(paper.y, paper.clean + paper.noise, atol=1e-12)
    np.testing.assert_allclose(paper.envelope, paper.amplitude * np.exp(1j * paper.phase))


def test_paper_signal_phase_convention(paper):
    fs = paper.fs
    # phi = 2 pi cumsum(f)/fs: the first sample already holds f[0]/fs
    np.testing.assert_allclose(paper.phi[:, 0], 2 * np.pi * paper.freqs[:, 0] / fs, rtol=1e-12)
    np.testing.assert_allclose(
        np.diff(paper.phi, axis=-1), 2 * np.pi * paper.freqs[:, 1:] / fs, rtol=1e-9, atol=1e-9
    )
    np.testing.assert_allclose(paper.phi, phase_from_freqs(paper.freqs, fs), rtol=0, atol=0)
    np.testing.assert_allclose(paper.phi, carrier_phase(paper.freqs, fs), rtol=0, atol=1e-9)


def test_paper_signal_frequency_is_physical(paper):
    """Zero crossings per second of X1 follow f1 (with 2*pi*f*t they would not)."""
    fs = int(paper.fs)
    x = paper.waveforms[0]
    for sec in (5, 20, 30, 44):
        seg = x[sec * fs : (sec + 1) * fs + 1]
        crossings = np.count_nonzero(np.signbit(seg[1:]) != np.signbit(seg[:-1]))
        expected = 2 * paper.freqs[0, sec * fs : (sec + 1) * fs].mean()
        # the printed 2*pi*f(t)*t would give f + t*df/dt (hundreds of Hz off at 30 s)
        assert abs(crossings - expected) <= 2.0, (sec, crossings, expected)


def test_paper_signal_noise(paper):
    noise = paper.noise
    assert noise.std() == pytest.approx(0.75, rel=0.01)
    assert abs(noise.mean()) < 0.01
    again = paper_signal(duration=1.0, seed=0)
    np.testing.assert_array_equal(again.y, paper_signal(duration=1.0, seed=0).y)
    assert not np.array_equal(again.y, paper_signal(duration=1.0, seed=1).y)
    quiet = paper_signal(duration=1.0, noise_std=0.0)
    np.testing.assert_array_equal(quiet.y, quiet.waveforms.sum(axis=0))


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"fs": 1000.0}, "fs"),
        ({"fs": -1.0}, "fs"),
        ({"duration": 0.0}, "duration"),
        ({"noise_std": -0.1}, "noise_std"),
    ],
)
def test_paper_signal_rejects_bad_arguments(kwargs, word):
    with pytest.raises(ValueError, match=word):
        paper_signal(**kwargs)


# ---------------------------------------------------------------- railway signal


@pytest.fixture(scope="module")
def rail():
    return railway_signal(duration=20.0, fs=2000.0, noise_std=0.5, seed=3)


def test_railway_signal_default_speed_profile(rail):
    v_kmh = rail.speed * 3.6
    assert v_kmh[0] == pytest.approx(40.0)
    assert v_kmh.max() == pytest.approx(200.0, rel=1e-6)
    assert np.argmax(v_kmh) == pytest.approx(rail.n_samples / 2, abs=2)
    assert v_kmh.min() >= 40.0 - 1e-9
    # smooth: no jumps (raised cosine)
    assert np.max(np.abs(np.diff(v_kmh))) < 0.1
    np.testing.assert_allclose(rail.position, np.cumsum(rail.speed) / rail.fs)


def test_railway_signal_orders(rail):
    v = rail.speed
    assert rail.freqs.shape == (12, rail.n_samples)
    assert rail.names[0] == "sleeper" and rail.names[11] == "wheel 11"
    np.testing.assert_allclose(rail.freqs[0], v / 0.6, rtol=1e-12)
    for order in range(1, 12):
        np.testing.assert_allclose(rail.freqs[order], order * v / (np.pi * 0.92), rtol=1e-12)
    # the sleeper order sits 4.817 wheel orders, i.e. 0.18 orders below wheel order 5
    ratio = rail.freqs[0] / rail.freqs[1]
    np.testing.assert_allclose(ratio, np.pi * 0.92 / 0.6, rtol=1e-12)
    assert ratio[0] == pytest.approx(4.817, abs=1e-3)
    # carriers: sleeper phase locked to distance, wheel order l = l * wheel angle
    np.testing.assert_allclose(rail.phi[0], 2 * np.pi * rail.position / 0.6, rtol=1e-9)
    theta = rail.position / (0.92 / 2)
    np.testing.assert_allclose(rail.phi[3], 3 * theta, rtol=1e-9)


def test_railway_signal_oor_amplitudes(rail):
    v = rail.speed
    for order in range(1, 12):
        omega = 2 * order * v / 0.92
        expected = DEFAULT_OOR_RADIUS_UM[order - 1] * 1e-6 * omega**2
        np.testing.assert_allclose(rail.amplitude[order], expected, rtol=1e-12)
        # radius phase psi -> acceleration phase psi + pi (constant per order)
        assert np.ptp(rail.phase[order]) == 0.0
    np.testing.assert_array_equal(rail.waveforms, rail.amplitude * np.cos(rail.phi + rail.phase))


def test_railway_oor_waveform_is_second_derivative_of_radius():
    """At constant speed a wheel order equals d²/dt² of rho cos(l theta + psi)."""
    fs = 20000.0
    sig = railway_signal(
        duration=0.5,
        fs=fs,
        speed_kmh=100.0,
        oor_radius_um=[0, 0, 0, 0, 30.0],
        oor_phase=[0, 0, 0, 0, 0.7],
        noise_std=0.0,
        sleeper_amplitude=0.0,
    )
    theta = 2 * sig.position / 0.92
    radius = 30e-6 * np.cos(5 * theta + 0.7)
    accel = np.gradient(np.gradient(radius, 1 / fs), 1 / fs)
    inner = slice(10, -10)
    np.testing.assert_allclose(
        sig.waveforms[5][inner], accel[inner], rtol=0, atol=1e-3 * np.abs(accel).max()
    )
    assert sig.phase[5, 0] == pytest.approx(0.7 - np.pi)
    np.testing.assert_allclose(sig.y, sig.waveforms[5], atol=1e-12)


def test_railway_signal_custom_inputs():
    fs = 1000.0
    n = 5000
    speed = np.linspace(50.0, 100.0, n)
    sig = railway_signal(
        duration=5.0,
        fs=fs,
        speed_kmh=speed,
        sleeper_amplitude=lambda t, x: 0.5 + 0.01 * x,
        sleeper_phase=0.3,
        oor_radius_um=[5.0, 1.0],
        oor_phase=[0.1, 0.2],
        seed=1,
    )
    assert sig.freqs.shape == (3, n)
    np.testing.assert_allclose(sig.speed, speed / 3.6)
    np.testing.assert_allclose(sig.amplitude[0], 0.5 + 0.01 * sig.position)
    np.testing.assert_array_equal(sig.phase[0], 0.3)
    np.testing.assert_allclose(
        sig.phase[1:, 0], np.angle(np.exp(1j * (np.array([0.1, 0.2]) + np.pi)))
    )
    sig2 = railway_signal(
        duration=5.0, fs=fs, speed_kmh=lambda t: 80 + 0 * t, sleeper_amplitude=2.0
    )
    np.testing.assert_allclose(sig2.speed, 80 / 3.6)
    np.testing.assert_array_equal(sig2.amplitude[0], 2.0)
    # standing train: speed 0 gives zero frequencies and zero OOR amplitude, no error
    stand = np.where(np.arange(n) < n // 2, 60.0, 0.0)
    sig3 = railway_signal(duration=5.0, fs=fs, speed_kmh=stand)
    assert np.all(sig3.freqs[:, n // 2 :] == 0.0)
    assert np.all(sig3.amplitude[1:, n // 2 :] == 0.0)


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"fs": 300.0}, "fs"),
        ({"speed_kmh": np.ones(7)}, "speed_kmh"),
        ({"speed_kmh": (-10.0, 50.0)}, "speed_kmh"),
        ({"wheel_diameter": 0.0}, "wheel_diameter"),
        ({"sleeper_spacing": -0.6}, "sleeper_spacing"),
        ({"oor_radius_um": [1.0, -2.0]}, "oor_radius_um"),
        ({"oor_phase": [0.0]}, "oor_phase"),
        ({"sleeper_amplitude": np.ones(3)}, "sleeper_amplitude"),
    ],
)
def test_railway_signal_rejects_bad_arguments(kwargs, word):
    args = {"duration": 2.0, "fs": 1000.0, **kwargs}
    with pytest.raises(ValueError, match=word):
        railway_signal(**args)
