"""The engine's exact solve (decimation off, one chunk) equals the paper's Eq. 20 (reference).

Eq. 20 as written leaves the orders' mirror images in the noise: the engine
solves it with ``real_signal=False`` (its default models the images, see
tests/vkf/test_vkf_engine.py for that form).

Settings are chosen so that the reference itself is well conditioned (B/fs large
enough for q = 3), see tests/vkf/test_reference_vkf.py for the reference's own checks.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from app.analysis.vkf import VKFResult, vkf
from tests.vkf.reference_vkf import carrier_phase, reference_vkf, weight_from_bandwidth

RTOL = 1e-6  # issue: "agreement to 1e-6 relative where no decimation is involved"
FS = 1000.0
N = 3000
BASE_BANDWIDTH = {1: 5.0, 2: 15.0, 3: 30.0}  # Hz at fs = 1 kHz


def _t() -> np.ndarray:
    return np.arange(N) / FS


def _orders(s: int) -> np.ndarray:
    """Instantaneous frequencies (s, N), Hz, time-varying; s = 3 and 12 include close orders."""
    t = _t()
    if s == 1:
        return (150 + 30 * np.sin(2 * np.pi * 0.5 * t))[None, :]
    if s == 3:
        f = 100 * (1 + 0.2 * np.sin(2 * np.pi * 0.4 * t))
        return np.vstack([f, 1.18 * f, np.full(N, 310.0)])  # orders 0 and 1: 0.18 f apart
    if s == 12:
        # the product's stack: sleeper passage (4.817 wheel orders) + wheel orders 1..11
        f1 = 40 + 3 * np.sin(2 * np.pi * 0.3 * t)
        return np.vstack([f1 * np.pi * 0.92 / 0.6] + [k * f1 for k in range(1, 12)])
    raise AssertionError(s)


def _bandwidth(s: int, q: int) -> np.ndarray | float:
    """Scalar for s = 1, (s, N) for s = 3 and 12 (time-varying, different per order)."""
    base = BASE_BANDWIDTH[q]
    if s == 1:
        return base
    t = _t()
    return base * (1 + 0.1 * np.sin(2 * np.pi * 0.5 * t[None, :] + np.arange(s)[:, None]))


def _signal(freqs: np.ndarray, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    s, n = freqs.shape
    phi = carrier_phase(freqs, FS)
    t = _t()
    amp = 1.0 + 0.3 * np.sin(2 * np.pi * (0.2 + 0.1 * np.arange(s))[:, None] * t)
    return np.sum(
        amp * np.cos(phi + rng.uniform(-np.pi, np.pi, (s, 1))), axis=0
    ) + 0.5 * rng.standard_normal(n)


def _exact_vkf(y, freqs, bandwidth, q, **kwargs) -> VKFResult:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # close orders are expected here
        return vkf(y, FS, freqs, bandwidth, q, decimation="off", chunk_duration=math.inf, real_signal=False,
                   **kwargs)


def _assert_matches_reference(envelope: np.ndarray, a_ref: np.ndarray) -> None:
    err = np.abs(envelope / 2 - a_ref).max()
    scale = np.abs(a_ref).max()
    assert err <= RTOL * scale, f"max |A - A_ref| / max |A_ref| = {err / scale:.2e} > {RTOL:.0e}"


@pytest.mark.parametrize("s", [1, 3, 12])
@pytest.mark.parametrize("q", [1, 2, 3])
def test_exact_solve_matches_reference(q: int, s: int) -> None:
    freqs = _orders(s)
    bandwidth = _bandwidth(s, q)
    y = _signal(freqs, seed=10 * q + s)
    res = _exact_vkf(y, freqs, bandwidth, q)
    r = weight_from_bandwidth(np.broadcast_to(bandwidth, freqs.shape), FS, q)
    a_ref = reference_vkf(y, carrier_phase(freqs, FS), r, q)
    assert res.envelope.shape == (s, N)
    _assert_matches_reference(res.envelope, a_ref)


@pytest.mark.parametrize("q", [1, 2, 3])
def test_per_order_bandwidth_and_phase0_match_reference(q: int) -> None:
    """(s,) bandwidth, constant (s,) freqs and phase0 against the reference."""
    freqs = np.array([140.0, 165.2, 290.0])
    bandwidth = BASE_BANDWIDTH[q] * np.array([1.0, 1.3, 0.8])
    phase0 = np.array([0.5, -2.0, 3.0])
    full = np.repeat(freqs[:, None], N, axis=1)
    y = _signal(full, seed=q)
    res = _exact_vkf(y, freqs, bandwidth, q, phase0=phase0)
    phi = carrier_phase(full, FS, phase0)
    np.testing.assert_allclose(res.phi, phi, rtol=0, atol=1e-9)
    a_ref = reference_vkf(y, phi, weight_from_bandwidth(bandwidth, FS, q), q)
    _assert_matches_reference(res.envelope, a_ref)


def test_multichannel_equals_per_channel() -> None:
    q, s = 2, 3
    freqs = _orders(s)
    bandwidth = _bandwidth(s, q)
    y = np.vstack([_signal(freqs, seed=k) for k in range(3)])
    res = _exact_vkf(y, freqs, bandwidth, q)
    assert res.envelope.shape == (3, s, N)
    assert res.waveform.shape == (3, s, N)
    assert res.residual.shape == (3, N)
    r = weight_from_bandwidth(bandwidth, FS, q)
    phi = carrier_phase(freqs, FS)
    for ch in range(3):
        single = _exact_vkf(y[ch], freqs, bandwidth, q)
        scale = np.abs(single.envelope).max()
        assert np.abs(res.envelope[ch] - single.envelope).max() <= 1e-9 * scale
        np.testing.assert_allclose(res.amplitude[ch], single.amplitude, rtol=0, atol=1e-9 * scale)
        _assert_matches_reference(res.envelope[ch], reference_vkf(y[ch], phi, r, q))


def test_result_fields_follow_the_contract() -> None:
    q, s = 2, 3
    freqs = _orders(s)
    bandwidth = 0.5 * _bandwidth(s, q)  # 6.75-8.25 Hz
    y = _signal(freqs, seed=5)
    phase0 = np.array([0.1, 0.2, -0.3])
    res = _exact_vkf(y, freqs, bandwidth, q, phase0=phase0)
    np.testing.assert_allclose(res.phi, carrier_phase(freqs, FS, phase0), rtol=0, atol=1e-9)
    assert res.fs == FS
    assert res.filter_order == q
    np.testing.assert_allclose(res.bandwidth, bandwidth, rtol=1e-12)
    assert res.bandwidth.shape == (s, N)
    assert res.envelope.dtype.kind == "c"
    np.testing.assert_allclose(res.amplitude, np.abs(res.envelope), rtol=1e-12, atol=0)
    np.testing.assert_allclose(
        np.exp(1j * res.phase), np.exp(1j * np.angle(res.envelope)), rtol=0, atol=1e-9
    )
    np.testing.assert_allclose(
        res.waveform, np.real(res.envelope * np.exp(1j * res.phi)), rtol=0, atol=1e-9
    )
    np.testing.assert_allclose(res.residual, y - res.waveform.sum(axis=-2), rtol=0, atol=1e-9)
    assert res.valid.shape == (s, N) and res.valid.dtype == bool
    assert res.valid.all()
    # orders 0 and 1 are 14.4-21.6 Hz apart, bandwidth <= 8.25 Hz: not close
    assert [tuple(sorted(p)) for p in res.close_orders] == []


def test_scalar_bandwidth_broadcasts() -> None:
    freqs = _orders(3)
    y = _signal(freqs, seed=8)
    res = _exact_vkf(y, freqs, 12.0, 2)
    assert res.bandwidth.shape == (3, N)
    np.testing.assert_array_equal(res.bandwidth, 12.0)
    res_full = _exact_vkf(y, freqs, np.full((3, N), 12.0), 2)
    np.testing.assert_allclose(res.envelope, res_full.envelope, rtol=0, atol=1e-12)
