"""The reference VKF of the tests is right on its own (no engine involved): dense least
squares, the minimum of the objective, the stationary response, close orders, refinement."""

from __future__ import annotations

import numpy as np
import pytest

from app.simulate.signals import paper_signal
from tests.vkf.reference_vkf import (
    carrier_phase,
    difference_matrix,
    reference_objective,
    reference_vkf,
    stationary_response,
    weight_from_bandwidth,
)


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
