"""Edge-preserving smoothing by the stated 1-σ (app.analysis.denoise): steps kept as sharp, the fluctuation
between them flattened, nothing done where the signal is strong against its 1-σ, stretches apart."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.denoise import edge_preserving


def _correlated_noise(rng, n, corr_bins=6):
    k = np.exp(-0.5 * (np.arange(-3 * corr_bins, 3 * corr_bins + 1) / corr_bins) ** 2)
    e = np.convolve(rng.standard_normal(n + k.size - 1), k / np.sqrt(np.sum(k**2)), mode="valid")
    return e


def test_a_small_step_under_noise_keeps_its_edge_and_loses_the_fluctuation():
    rng = np.random.default_rng(3)
    n = 1600
    bins = np.arange(n)
    truth = np.where(bins < 800, 1.5, 1.0)  # the −35 % step of issue 33, 1.5 → 1.0 m/s²
    sd = np.full(n, 0.05)
    y = truth + sd * _correlated_noise(rng, n)
    u = edge_preserving(bins, y, sd, 8.0)
    s_y, s_u = (y - 1.5) / -0.5, (u - 1.5) / -0.5
    far = np.abs(bins - 800) > 40
    assert np.abs(s_u[far] - (bins[far] >= 800)).max() < 0.5 * np.abs(s_y[far] - (bins[far] >= 800)).max()
    assert np.std(u[:700]) < 0.7 * np.std(y[:700])
    # the edge where it was: the 50 % point within a metre (4 bins), the levels the data's
    x50 = np.flatnonzero((s_u[:-1] < 0.5) & (s_u[1:] >= 0.5))
    assert x50.size == 1 and abs(int(x50[0]) - 800) <= 4
    assert np.mean(u[100:700]) == pytest.approx(np.mean(y[100:700]), abs=0.01)


def test_a_strong_signal_is_left_as_it_is_and_bad_bins_break_the_stretch():
    bins = np.arange(200)
    y = 2.0 + 0.5 * np.sin(bins / 7.0)
    sd = np.full(200, 1e-4)  # a noise-free record states a tiny 1-σ
    np.testing.assert_allclose(edge_preserving(bins, y, sd, 8.0), y, atol=2e-3)
    y2, sd2 = y.copy(), np.full(200, 0.3)
    y2[100] = np.nan
    sd2[50] = np.nan
    out = edge_preserving(bins, y2, sd2, 8.0)
    assert np.isnan(out[100]) and out[50] == y2[50]
    gap = edge_preserving(np.r_[bins[:100], bins[100:] + 10], y, np.full(200, 0.3), 8.0)
    assert np.isfinite(gap).all()
    assert edge_preserving(bins, y, sd2, 0.0) is not y and np.array_equal(edge_preserving(bins, y, sd2, 0.0), y)
    with pytest.raises(ValueError, match="kappa"):
        edge_preserving(bins, y, sd, -1.0)
    with pytest.raises(ValueError, match="equal length"):
        edge_preserving(bins[:-1], y, sd, 1.0)
