"""Tests of app.analysis.wheel_oor against synthetic envelopes with known OOR."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.analysis.wheel_oor import (
    apply_diameter_correction,
    radius_phasor,
    reconstruct_profile,
    refine_diameter,
    summarize_oor,
    window_means,
)

ORDERS = np.arange(1, 12)
D_W = 0.92
RHO_UM = np.array([40.0, 25.0, 90.0, 15.0, 30.0, 10.0, 12.0, 8.0, 6.0, 5.0, 4.0])
PSI = np.linspace(-2.9, 3.0, 11)


def _speed(n: int, fs: float) -> np.ndarray:
    t = np.arange(n) / fs
    v = 20.0 + 15.0 * np.sin(2 * np.pi * t / t[-1])  # 5..35 m/s
    return v


def _envelopes(distance: np.ndarray, speed: np.ndarray, d_true: float, d_nom: float) -> np.ndarray:
    """VKF envelopes (m/s²) of a wheel of true diameter d_true tracked with d_nom."""
    theta_true = 2 * distance / d_true
    theta_nom = 2 * distance / d_nom
    omega_true = 2 * ORDERS[:, None] * speed[None, :] / d_true
    phasor_m = (RHO_UM * 1e-6 * np.exp(1j * PSI))[:, None]
    drift = np.exp(1j * ORDERS[:, None] * (theta_true - theta_nom)[None, :])
    return -phasor_m * omega_true**2 * drift


def test_radius_phasor_recovers_known_oor() -> None:
    fs = 500.0
    v = _speed(20_000, fs)
    v[5_000:5_200] = 0.0  # standstill
    s = np.cumsum(v) / fs
    env = _envelopes(s, v, D_W, D_W)
    rho = radius_phasor(env, v, D_W, ORDERS)
    assert rho.shape == (11, v.size)
    assert np.all(np.isnan(rho[:, 5_000:5_200]))
    moving = v > 0
    expected = (RHO_UM * np.exp(1j * PSI))[:, None]
    err = np.abs(rho[:, moving] - expected)
    assert err.max() < 1e-9


def test_sign_convention_matches_waveform() -> None:
    # a single raised spot on the wheel: the axle is pushed up when the spot is in
    # contact, the acceleration there is negative (-rho omega^2 cos), the waveform is
    # Re(e exp(j l theta)): check radius_phasor inverts that exactly.
    v = np.full(1000, 30.0)
    theta = 2 * np.cumsum(v) / 1000.0 / D_W
    rho_m, psi, order = 50e-6, 0.4, 2
    omega = 2 * order * v / D_W
    accel = -rho_m * omega**2 * np.cos(order * theta + psi)  # d²/dt² of rho cos(...)
    # envelope as the VKF would deliver it for this waveform
    env = (rho_m * omega**2 * np.exp(1j * (psi + np.pi)))[None, :]
    np.testing.assert_allclose(np.real(env[0] * np.exp(1j * order * theta)), accel, atol=1e-12)
    got = radius_phasor(env, v, D_W, [order])
    np.testing.assert_allclose(got, 50.0 * np.exp(1j * psi), rtol=1e-12)


def test_window_means_matches_direct_computation() -> None:
    rng = np.random.default_rng(11)
    n = 5_000
    s = np.sort(rng.uniform(3.0, 300.0, n))
    s[2_000:2_400] = np.linspace(120.0, 121.0, 400)  # no samples in [121.x, ...) for a while
    vals = rng.normal(size=(2, n)) + 1j * rng.normal(size=(2, n))
    vals[0, rng.random(n) < 0.2] = np.nan
    w = rng.uniform(0.0, 1.0, n)
    w[rng.random(n) < 0.1] = 0.0
    got, centres = window_means(vals, s, 10.0, w)
    idx = np.floor(s / 10.0).astype(int)
    present = sorted(set(idx[w > 0]))
    np.testing.assert_allclose(centres, (np.array(present) + 0.5) * 10.0)
    for j, wi in enumerate(present):
        for i in range(2):
            m = (idx == wi) & (w > 0) & np.isfinite(vals[i])
            ref = np.sum(w[m] * vals[i, m]) / np.sum(w[m]) if m.any() else np.nan
            np.testing.assert_allclose(got[i, j], ref, rtol=1e-12, equal_nan=True)


def _windows_with_drift(
    d_true: float, noise_um: float, length_m: float = 3_000.0, seed: int = 12
) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    fs = 400.0
    n = int(length_m / 20.0 * fs)
    v = _speed(n, fs)
    s = np.cumsum(v) / fs
    env = _envelopes(s, v, d_true, D_W)
    rho = radius_phasor(env, v, D_W, ORDERS)
    rho += noise_um * (rng.normal(size=rho.shape) + 1j * rng.normal(size=rho.shape))
    return window_means(rho, s, 10.0)


def test_refine_diameter_recovers_03_percent_error() -> None:
    d_true = D_W * 1.003
    win, centres = _windows_with_drift(d_true, noise_um=60.0)
    # the drift is visible: order 3's phase turns by several radians over the run
    ph = np.unwrap(np.angle(win[2]))
    assert abs(ph[-1] - ph[0]) > 5.0
    d = refine_diameter(win, centres, D_W, order=ORDERS)
    assert abs(d / d_true - 1) < 5e-4
    # int order = first order of consecutive rows
    assert refine_diameter(win, centres, D_W, order=1) == d
    # corrected phasors refer to the true wheel angle: phases and radii come back
    fixed = apply_diameter_correction(win, centres, ORDERS, D_W, d)
    summary = summarize_oor(fixed, ORDERS)
    for row, rho, psi in zip(summary["orders"], RHO_UM, PSI, strict=True):
        mean_err = abs(np.angle(np.exp(1j * (row["phase_rad"] - psi))))
        assert mean_err < 0.1, row
        if rho >= 20.0:  # weak orders: |phasor| is biased up by the noise (Rice)
            assert abs(row["radius_um"] / rho - 1) < 0.05, row


@pytest.mark.parametrize("seed", [1, 3, 4])
def test_refine_diameter_low_snr_with_gaps(seed: int) -> None:
    # per-window phase noise ~1 rad on the strongest order, windows missing in blocks
    # and at random (amplitude gate): no 2 pi slips, the drift is still found
    d_true = D_W * 1.003
    win, centres = _windows_with_drift(d_true, noise_um=1000.0, seed=seed)
    keep = np.ones(centres.size, bool)
    keep[40:75] = False
    keep[200:203] = False
    d = refine_diameter(win[:, keep], centres[keep], D_W, order=ORDERS)
    assert abs(d / d_true - 1) < 5e-4


def test_refine_diameter_negative_drift_and_clip() -> None:
    d_true = D_W * 0.996
    win, centres = _windows_with_drift(d_true, noise_um=20.0, length_m=2_000.0)
    d = refine_diameter(win, centres, D_W, order=ORDERS)
    assert abs(d / d_true - 1) < 5e-4
    win, centres = _windows_with_drift(D_W * 1.08, noise_um=0.0, length_m=1_000.0)
    assert refine_diameter(win, centres, D_W, order=ORDERS) == pytest.approx(D_W * 1.05)


def test_refine_diameter_returns_nominal_without_evidence() -> None:
    rng = np.random.default_rng(13)
    centres = (np.arange(300) + 0.5) * 10.0
    noise = rng.normal(size=(11, 300)) + 1j * rng.normal(size=(11, 300))
    assert refine_diameter(noise, centres, D_W, order=ORDERS) == D_W
    win, centres = _windows_with_drift(D_W * 1.003, noise_um=1.0)
    assert refine_diameter(win[:, :4], centres[:4], D_W, order=ORDERS) == D_W  # too few
    assert refine_diameter(np.full((11, 50), np.nan + 0j), centres[:50], D_W) == D_W
    with pytest.raises(ValueError, match="nominal_diameter"):
        refine_diameter(win, centres, -1.0)
    with pytest.raises(ValueError, match="order"):
        refine_diameter(win, centres, D_W, order=[1, 2])


def test_reconstruct_single_order_is_a_cosine() -> None:
    prof = reconstruct_profile(np.array([50.0 * np.exp(1j * 0.7)]), [3], n_angles=3600)
    theta = 2 * np.pi * np.arange(3600) / 3600
    np.testing.assert_allclose(prof, 50.0 * np.cos(3 * theta + 0.7), atol=1e-12)
    # grid of 0.1 deg: the sampled peak is within 3 * half a step of the true one
    assert 50.0 * np.cos(3 * np.pi / 3600) <= prof.max() <= 50.0
    peak = theta[np.argmax(prof)]
    # peaks at 3 theta + 0.7 = 2 pi k
    expected = (2 * np.pi * np.arange(1, 4) - 0.7) / 3
    assert np.min(np.abs(expected - peak)) < 2 * np.pi / 3600
    # superposition and batch form
    two = reconstruct_profile(np.array([10.0, 5j]), [1, 2], n_angles=8)
    th = 2 * np.pi * np.arange(8) / 8
    np.testing.assert_allclose(two, 10 * np.cos(th) - 5 * np.sin(2 * th), atol=1e-12)
    batch = reconstruct_profile(np.array([[10.0, 1.0], [5j, 0.0]]), [1, 2], n_angles=8)
    np.testing.assert_allclose(batch[0], two, atol=1e-12)


def test_summarize_noisy_windows() -> None:
    rng = np.random.default_rng(14)
    n_w = 400
    truth = RHO_UM * np.exp(1j * PSI)
    win = truth[:, None] + 8.0 * (rng.normal(size=(11, n_w)) + 1j * rng.normal(size=(11, n_w)))
    win[:, :7] = np.nan  # standing: unusable windows
    win[4, 10] = np.nan
    out = summarize_oor(win, ORDERS)
    json.dumps(out)  # JSON-ready
    assert out["n_windows"] == n_w - 8
    assert len(out["angles_deg"]) == 360 and out["angles_deg"][1] == 1.0
    for row, rho, psi in zip(out["orders"], RHO_UM, PSI, strict=True):
        assert row["radius_um_p05"] <= row["radius_um"] <= row["radius_um_p95"]
        # mean of n windows: phase error ~ sigma / (rho sqrt(n)); allow 4 sigma
        tol = 4 * 8.0 / (rho * np.sqrt(out["n_windows"]))
        assert abs(np.angle(np.exp(1j * (row["phase_rad"] - psi)))) < tol
    p05, p95, prof = (np.array(out[k]) for k in ("profile_p05_um", "profile_p95_um", "profile_um"))
    assert np.all(p05 <= prof) and np.all(prof <= p95)
    ref = reconstruct_profile(truth, ORDERS)
    assert np.max(np.abs(prof - ref)) < 5.0  # mean of 392 windows, noise 8 µm per component
    empty = summarize_oor(np.full((11, 3), np.nan + 0j), ORDERS)
    assert empty["n_windows"] == 0 and np.isnan(empty["profile_um"]).all()


def test_validation() -> None:
    v = np.ones(5)
    env = np.ones((2, 5), complex)
    with pytest.raises(ValueError, match="speed"):
        radius_phasor(env, np.ones(4), D_W, [1, 2])
    with pytest.raises(ValueError, match="wheel_diameter"):
        radius_phasor(env, v, 0.0, [1, 2])
    with pytest.raises(ValueError, match="orders"):
        radius_phasor(env, v, D_W, [0, 1])
    with pytest.raises(ValueError, match="orders"):
        radius_phasor(env, v, D_W, [1, 2, 3])
    with pytest.raises(ValueError, match="window_m"):
        window_means(env, np.arange(5.0), 0.0)
    with pytest.raises(ValueError, match="distance_m"):
        window_means(env, np.array([0, 1, np.nan, 3, 4]), 1.0)
    with pytest.raises(ValueError, match="n_angles"):
        reconstruct_profile(np.ones(2), [1, 2], n_angles=0)
