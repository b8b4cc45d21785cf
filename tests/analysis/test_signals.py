"""The synthetic signals and the reference VKF are right on their own (no engine involved)."""

from __future__ import annotations

import numpy as np
import pytest

from app.simulate.signals import (
    DEFAULT_OOR_RADIUS_UM,
    paper_signal,
    phase_from_freqs,
    railway_signal,
)
from tests.analysis.reference_vkf import (
    carrier_phase,
    difference_matrix,
    reference_objective,
    reference_vkf,
    stationary_response,
    weight_from_bandwidth,
)

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


# ---------------------------------------------------------------- the reference solver


def test_difference_matrix_matches_np_diff():
    for q in (1, 2, 3):
        dense = difference_matrix(9, q).toarray()
        np.testing.assert_array_equal(dense, np.diff(np.eye(9), n=q, axis=0))
        assert dense.shape == (9 - q, 9)


def test_weight_gives_minus_3db_at_half_bandwidth():
    for q in (1, 2, 3):
        for b, fs in ((0.5, 24000.0), (1.5, 12000.0), (50.0, 1000.0)):
            assert stationary_response(b / 2, b, fs, q) == pytest.approx(2**-0.5, rel=1e-12)
            assert stationary_response(0.0, b, fs, q) == 1.0
            assert stationary_response(b, b, fs, q) < 2**-0.5


def _dense_stacked_lstsq(y, phi, r_full, q):
    """Same problem, solved as an overdetermined least-squares system (no normal equations)."""
    s, n = phi.shape
    c = np.hstack([np.diag(np.exp(1j * p)) for p in phi])
    d = np.diff(np.eye(n), n=q, axis=0)
    rows = [c]
    for k in range(s):
        block = np.zeros((n - q, s * n))
        block[:, k * n : (k + 1) * n] = r_full[k, q:, None] * d
        rows.append(block)
    rhs = np.concatenate([y, np.zeros(s * (n - q))])
    a = np.linalg.lstsq(np.vstack(rows), rhs, rcond=None)[0]
    return a.reshape(s, n)


@pytest.mark.parametrize(("q", "bandwidth"), [(1, 5.0), (2, 15.0), (3, 40.0)])
def test_reference_matches_dense_least_squares(q, bandwidth):
    fs, n = 1000.0, 150
    t = np.arange(n) / fs
    freqs = np.vstack([100 + 80 * t, 100 + 80 * t + 18 + 5 * np.sin(2 * np.pi * 4 * t)])
    phi = carrier_phase(freqs, fs, phase0=[0.2, -1.0])
    rng = np.random.default_rng(q)
    y = np.cos(phi[0]) + 0.5 * np.cos(phi[1] + 1) + 0.3 * rng.standard_normal(n)
    b = bandwidth * (1 + 0.3 * np.sin(2 * np.pi * 10 * t[None, :] + np.array([[0.0], [1.0]])))
    r = weight_from_bandwidth(b, fs, q)
    a_ref = reference_vkf(y, phi, r, q)
    a_dense = _dense_stacked_lstsq(y, phi, r, q)
    scale = np.abs(a_dense).max()
    assert np.abs(a_ref - a_dense).max() <= 1e-7 * scale
    # and it is the minimum of the objective (paper Eq. 19), computed with np.diff
    v0 = reference_objective(y, phi, r, q, a_ref)
    for _ in range(3):
        da = 1e-3 * (rng.standard_normal(a_ref.shape) + 1j * rng.standard_normal(a_ref.shape))
        assert reference_objective(y, phi, r, q, a_ref + da) > v0


def test_reference_weights_per_row():
    """(s, N) weights: row i of order n (difference ending at sample i) gets r[n, i]."""
    fs, n, q = 1000.0, 150, 2
    phi = carrier_phase(np.array([[120.0], [260.0]]) * np.ones(n), fs)
    rng = np.random.default_rng(7)
    y = rng.standard_normal(n)
    r = np.vstack([np.linspace(5.0, 50.0, n), np.linspace(80.0, 8.0, n)])
    a_ref = reference_vkf(y, phi, r, q)
    np.testing.assert_allclose(a_ref, _dense_stacked_lstsq(y, phi, r, q), rtol=0, atol=1e-9)
    # the scalar / (s,) forms are the broadcast of the full form
    np.testing.assert_allclose(
        reference_vkf(y, phi, [10.0, 20.0], q),
        reference_vkf(y, phi, np.repeat([[10.0], [20.0]], n, axis=1), q),
        atol=1e-12,
    )
    np.testing.assert_allclose(
        reference_vkf(y, phi, 10.0, q), reference_vkf(y, phi, [10.0, 10.0], q), atol=1e-12
    )


def test_reference_with_tiny_weight_reproduces_the_signal():
    """r -> 0: the complex model sum_n A_n exp(j phi_n) interpolates y exactly."""
    fs, n = 2000.0, 1000
    sig = paper_signal(duration=n / fs, fs=fs, noise_std=0.2, seed=4)
    a = reference_vkf(sig.y, sig.phi, 1e-6, 2)
    model = np.sum(a * np.exp(1j * sig.phi), axis=0)
    np.testing.assert_allclose(model, sig.y, rtol=0, atol=1e-8)


@pytest.mark.parametrize(("q", "bandwidth"), [(1, 2.0), (2, 10.0), (3, 30.0)])
def test_reference_recovers_a_clean_tone(q, bandwidth):
    fs, n = 1000.0, 3000
    freqs = np.full((1, n), 123.4)
    phi = carrier_phase(freqs, fs)
    y = 0.8 * np.cos(phi[0] + 0.3)
    a = reference_vkf(y, phi, weight_from_bandwidth(bandwidth, fs, q), q)
    env = 2 * a[0]
    # the negative-frequency image (offset 2*f0) leaks in with the stationary response
    leak = 0.8 * stationary_response(2 * 123.4, bandwidth, fs, q)
    inner = slice(1000, -1000)
    assert np.abs(env[inner] - 0.8 * np.exp(0.3j)).max() <= 1.5 * leak + 1e-9


@pytest.mark.parametrize("q", [1, 2, 3])
def test_reference_stationary_response_at_half_bandwidth(q):
    """The reference's response to a tone B/2 off the tracked frequency is -3 dB."""
    fs, bandwidth, f0 = 1000.0, 40.0, 250.0
    n = 4000
    phi_track = carrier_phase(np.full((1, n), f0), fs)
    for offset in (+bandwidth / 2, -bandwidth / 2, bandwidth / 4):
        y = np.cos(carrier_phase(np.full((1, n), f0 + offset), fs)[0])
        a = reference_vkf(y, phi_track, weight_from_bandwidth(bandwidth, fs, q), q)
        amp = np.abs(2 * a[0, 1500:-1500]).mean()
        assert amp == pytest.approx(stationary_response(offset, bandwidth, fs, q), rel=2e-3)


def test_reference_separates_close_orders():
    """Two tones 0.18*f apart, each tracked: both envelopes come back (coupled solve)."""
    fs, n = 1000.0, 6000
    t = np.arange(n) / fs
    f = 100 + 20 * np.sin(2 * np.pi * 0.2 * t)
    freqs = np.vstack([f, 1.18 * f])
    phi = carrier_phase(freqs, fs)
    a_true = np.vstack([1.0 + 0.2 * np.sin(2 * np.pi * 0.3 * t), np.full(n, 0.5)])
    p_true = np.array([[0.4], [-2.0]])
    y = np.sum(a_true * np.cos(phi + p_true), axis=0)
    a = reference_vkf(y, phi, weight_from_bandwidth(4.0, fs, 2), 2)
    env = 2 * a
    inner = slice(1000, -1000)
    err = np.abs(env[:, inner] - a_true[:, inner] * np.exp(1j * p_true))
    assert err.max() <= 0.01


def test_reference_refinement_reaches_the_exact_solution():
    """Hardest reference setting (q = 3, 12 orders with a close pair): refined solve is exact.

    The extended-precision residual of the normal equations after refinement is at the
    rounding level, and the plain double solve differs from it by no more than cond*eps.
    """
    fs, n, q = 1000.0, 3000, 3
    t = np.arange(n) / fs
    f1 = 40 + 3 * np.sin(2 * np.pi * 0.3 * t)
    freqs = np.vstack([f1 * np.pi * 0.92 / 0.6] + [k * f1 for k in range(1, 12)])
    phi = carrier_phase(freqs, fs)
    rng = np.random.default_rng(0)
    y = np.sum(np.cos(phi + rng.uniform(-3, 3, (12, 1))), axis=0) + 0.5 * rng.standard_normal(n)
    r = weight_from_bandwidth(30.0, fs, q)
    a = reference_vkf(y, phi, r, q)
    a_more = reference_vkf(y, phi, r, q, refine=8)
    a_plain = reference_vkf(y, phi, r, q, refine=0)
    scale = np.abs(a).max()
    assert np.abs(a - a_more).max() <= 1e-8 * scale
    assert np.abs(a - a_plain).max() <= 1e-4 * scale  # cond ~1e11: the plain solve is poorer
