"""app.analysis.uncertainty: along-track correlation of a track order's envelope, the power model, segments.

Checked against independent references: the correlation by direct numerical integration of the
filter's squared response, the segment rule by Monte Carlo through the real VKF, the moments by
sampling.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.integrate import quad

from app.analysis.recipe import STEP_WIDTH_FACTOR, order_recipe
from app.analysis.settings import ProcessingSettings
from app.analysis.uncertainty import (
    STEP_WIDTH_FACTORS,
    clipped_sqrt_moments,
    correlation_length,
    envelope_correlation,
    segment_sd,
)


def test_step_width_factors_are_the_recipes():
    assert STEP_WIDTH_FACTORS == STEP_WIDTH_FACTOR


@pytest.mark.parametrize("q", [1, 2, 3])
@pytest.mark.parametrize("res", [2.0, 3.0, 6.0])
def test_correlation_against_direct_integration(q, res):
    b = STEP_WIDTH_FACTOR[q] / res  # full -3 dB bandwidth, cycles per m

    def h2(k):
        return (1.0 / (1.0 + (np.sqrt(2.0) - 1.0) * (2.0 * k / b) ** (2 * q))) ** 2

    norm = quad(h2, 0, np.inf, limit=400)[0]
    for lag in (0.0, 0.5, 1.3, 2.7, 4.0, 7.5):
        ref = quad(lambda k, lag=lag: h2(k) * np.cos(2 * np.pi * k * lag), 0, 40 * b, limit=800)[0] / norm
        assert envelope_correlation(lag, res, q) == pytest.approx(ref, abs=2e-4)
    assert correlation_length(res, q) == pytest.approx(1.0 / (2.0 * norm), rel=1e-4)


def test_correlation_length_of_the_default():
    assert correlation_length() == pytest.approx(4.01, abs=0.01)
    assert correlation_length(6.0) == pytest.approx(2 * correlation_length(3.0))


def test_segment_sd_matches_monte_carlo_through_the_vkf():
    """White noise through the real recipe: the scatter of 10 m and 40 m means of the sleeper envelope's
    real part against segment_sd of its per-bin scatter."""
    fs, v = 2000.0, 35.0
    recipe = order_recipe(0.92, 0.6, ProcessingSettings())
    rng = np.random.default_rng(3)
    n = int(fs * 2000 / v)  # 2 km
    y = rng.standard_normal(n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = recipe.solve(y, fs, np.full(n, v))
    step = int(fs * 0.05 / v)
    idx = np.arange(0, n, step)
    e = res.envelope_at(idx)[recipe.sleeper_row].real
    b = np.floor(idx * v / fs / 0.25).astype(np.int64)
    per_bin = np.bincount(b, e) / np.bincount(b)
    bins = np.arange(per_bin.size)
    inner = slice(200, -200)
    sd_bin = per_bin[inner].std()
    for level in (10.0, 40.0):
        k = int(level / 0.25)
        _, g = np.unique(bins[inner] // k, return_inverse=True)
        means = np.bincount(g, per_bin[inner]) / np.bincount(g)
        segs, sd = segment_sd(bins[inner], np.full(bins[inner].size, sd_bin), level)
        assert np.std(means[1:-1]) == pytest.approx(np.median(sd), rel=0.2), level


def test_segment_sd_limits():
    bins = np.arange(400)
    sd = np.full(400, 2.0)
    # one bin per segment: the bin's own sd
    segs, s = segment_sd(bins, sd, 0.25)
    np.testing.assert_allclose(s, 2.0)
    # long segments: sd * sqrt(l / L)
    segs, s = segment_sd(bins, sd, 100.0)
    assert s[0] == pytest.approx(2.0 * np.sqrt(correlation_length() / 100.0), rel=0.02)
    # a very fine resolution: bins independent, sd / sqrt(n)
    segs, s = segment_sd(bins, sd, 10.0, resolution_m=0.01)
    np.testing.assert_allclose(s, 2.0 / np.sqrt(40), rtol=1e-6)
    # NaN bins are left out; gaps count as gaps
    sd2 = sd.copy()
    sd2[:40] = np.nan
    segs, s = segment_sd(bins, sd2, 10.0)
    assert segs[0] == 1 and s.size == 9


def test_segment_sd_rejects_bad_input():
    with pytest.raises(ValueError, match="one length"):
        segment_sd(np.arange(3), np.ones(4), 1.0)
    with pytest.raises(ValueError, match="unique"):
        segment_sd(np.array([1, 1, 2]), np.ones(3), 1.0)
    with pytest.raises(ValueError, match="multiple"):
        segment_sd(np.arange(3), np.ones(3), 0.3)
    with pytest.raises(ValueError, match="integers"):
        segment_sd(np.arange(3.0), np.ones(3), 1.0)
    with pytest.raises(ValueError, match="filter_order"):
        envelope_correlation(1.0, 3.0, 4)
    with pytest.raises(ValueError, match="resolution_m"):
        correlation_length(0.0)


@pytest.mark.parametrize("mu, sigma", [(3.0, 1.0), (0.5, 1.0), (-1.0, 2.0), (40.0, 1.0), (2.0, 0.0)])
def test_clipped_sqrt_moments_against_sampling(mu, sigma):
    x = mu + sigma * np.random.default_rng(0).standard_normal(2_000_000)
    m_sqrt, m_pos = clipped_sqrt_moments(mu, sigma)
    assert float(m_sqrt) == pytest.approx(np.sqrt(np.maximum(x, 0)).mean(), rel=2e-3, abs=1e-4)
    assert float(m_pos) == pytest.approx(np.maximum(x, 0).mean(), rel=2e-3, abs=1e-4)
    with pytest.raises(ValueError, match="sigma"):
        clipped_sqrt_moments(1.0, -1.0)


@pytest.mark.parametrize("s2, f, t", [(1.0, 0.43, 0.43), (1.0, 3.0, 3.0), (1.0, 3.0, 1.0), (0.01, 1.0, 1.0),
                                      (100.0, 1.0, 1.0), (0.0, 1.0, 0.5), (4.0, 0.0, 1.0)])
def test_rice_clipped_moments_against_sampling(s2, f, t):
    from app.analysis.uncertainty import rice_clipped_moments

    rng = np.random.default_rng(1)
    r = np.sqrt(f / 2) * (rng.standard_normal(1_000_000) + 1j * rng.standard_normal(1_000_000))
    p = np.abs(np.sqrt(s2) + r) ** 2
    m_sqrt, m_pos = rice_clipped_moments(s2, f, t)
    assert float(m_sqrt) == pytest.approx(np.sqrt(np.maximum(p - t, 0)).mean(), rel=5e-3, abs=1e-4)
    assert float(m_pos) == pytest.approx(np.maximum(p - t, 0).mean(), rel=5e-3, abs=1e-4)


def test_aggregate_profile_gives_the_segments_sd():
    import pandas as pd

    from app.analysis.aggregate import aggregate_profile

    rng = np.random.default_rng(2)
    bins = np.arange(1000, 1400)
    df = pd.DataFrame({"bin": bins, "sleeper_amp": rng.random(400), "sleeper_amp_sd": rng.uniform(0.1, 0.2, 400)})
    df = df.drop(index=[5, 6, 7])  # a gap
    out = aggregate_profile(df.sample(frac=1.0, random_state=1), 10.0, ["sleeper_amp", "sleeper_amp_sd"])
    segs, sd = segment_sd(df["bin"].to_numpy(), df["sleeper_amp_sd"].to_numpy(), 10.0)
    np.testing.assert_allclose(out["sleeper_amp_sd_mean"], sd)
    np.testing.assert_allclose(out["km_from"], segs * 10.0 / 1000)
    assert (out["sleeper_amp_sd_max"] >= out["sleeper_amp_sd_mean"]).all()
    # another resolution, another correlation
    wide = aggregate_profile(df, 10.0, ["sleeper_amp_sd"], resolution_m=6.0)
    assert (wide["sleeper_amp_sd_mean"] > out["sleeper_amp_sd_mean"]).all()


@pytest.mark.parametrize("s2, f1, f2", [(32.0, 43.0, 54.0), (144.0, 173.0, 239.0), (0.56, 2.5, 3.0), (32.0, 5.0, 5.0),
                                        (1.0, 100.0, 0.1), (1e-5, 3.0, 4.0), (1e4, 1.0, 2.0), (3.0, 0.0, 4.0)])
def test_cross_rail_moments_against_sampling(s2, f1, f2):
    """X = Re((S + R1) conj(S + R2)), R_i circular Gaussian: sampled, against the tabulated quadrature."""
    from app.analysis.uncertainty import cross_rail_moments

    rng = np.random.default_rng(4)
    n = 1_000_000
    r1 = np.sqrt(f1 / 2) * (rng.standard_normal(n) + 1j * rng.standard_normal(n))
    r2 = np.sqrt(f2 / 2) * (rng.standard_normal(n) + 1j * rng.standard_normal(n))
    x = np.real((np.sqrt(s2) + r1) * np.conj(np.sqrt(s2) + r2))
    m_sqrt, m_pos = cross_rail_moments(s2, f1, f2)
    assert float(m_sqrt) == pytest.approx(np.sqrt(np.maximum(x, 0)).mean(), rel=1e-2)
    assert float(m_pos) == pytest.approx(np.maximum(x, 0).mean(), rel=1e-2)
    assert cross_rail_moments(s2, f2, f1)[0] == pytest.approx(float(m_sqrt), rel=1e-9)  # the rails are alike


def test_cross_rail_moments_are_not_the_gaussian_models():
    """At S² ≈ 0.7 F the cross product is skewed: a Gaussian of its variance puts E sqrt(X⁺) 5 % high."""
    from app.analysis.uncertainty import cross_rail_moments

    s2, f1, f2 = 32.0, 43.0, 54.0
    gauss, _ = clipped_sqrt_moments(s2, np.sqrt(s2 * (f1 + f2) / 2 + f1 * f2 / 2))
    exact, _ = cross_rail_moments(s2, f1, f2)
    assert float(gauss) / float(exact) - 1 == pytest.approx(0.05, abs=0.015)


def _brute_segment_sd(bins, sd, shared, level, res=3.0, q=2):
    from app.analysis.uncertainty import shared_correlation

    rnd = np.sqrt(sd**2 - shared**2)
    out = {}
    for g in np.unique(bins // int(level / 0.25)):
        m = bins // int(level / 0.25) == g
        lag = np.abs(bins[m][:, None] - bins[m][None, :]) * 0.25
        cov = (np.outer(rnd[m], rnd[m]) * envelope_correlation(lag, res, q)
               + np.outer(shared[m], shared[m]) * shared_correlation(lag, res, q))
        out[int(g)] = np.sqrt(cov.sum()) / m.sum()
    return out


def test_segment_sd_with_a_shared_part_against_the_double_sum():
    rng = np.random.default_rng(5)
    bins = np.setdiff1d(np.arange(200, 900), [300, 301, 302, 650])
    sd = rng.uniform(0.5, 1.5, bins.size)
    shared = sd * rng.uniform(0.0, 0.9, bins.size)
    for level in (10.0, 40.0):
        segs, s = segment_sd(bins, sd, level, shared=shared)
        ref = _brute_segment_sd(bins, sd, shared, level)
        np.testing.assert_allclose(s, [ref[int(g)] for g in segs], rtol=1e-9)
    # all shared: a 10 m mean barely averages it down; none shared: the rule of old
    _, s_all = segment_sd(bins, sd, 10.0, shared=sd)
    _, s_none = segment_sd(bins, sd, 10.0, shared=np.zeros_like(sd))
    _, s_old = segment_sd(bins, sd, 10.0)
    np.testing.assert_allclose(s_none, s_old)
    assert np.all(s_all[:-1] > 1.4 * s_old[:-1])  # (the last segment holds 5 m)
    with pytest.raises(ValueError, match="shared"):
        segment_sd(bins, sd, 10.0, shared=sd[:-1])


def test_segment_sd_shared_part_matches_monte_carlo():
    """A floor estimated as a 20 m moving mean of white looks plus the envelope's broadband part: the scatter
    of 10 m and 40 m means against segment_sd with that floor's error stated as shared."""
    from app.analysis.uncertainty import shared_window_m

    rng = np.random.default_rng(6)
    n_bins, reps = 4000, 400
    bins = np.arange(n_bins)
    # the broadband part: white noise through the envelope's correlation (an FIR of the filter's response)
    lag = np.arange(-64, 65) * 0.25
    kernel = np.real(np.fft.ifft(np.sqrt(np.abs(np.fft.fft(envelope_correlation(lag))))))
    kernel = np.roll(kernel, 64)
    w = int(round(shared_window_m() / 0.25))
    err = []
    for _ in range(reps):
        a = np.convolve(rng.standard_normal(n_bins + 128), kernel, mode="same")[64:-64]
        a /= np.sqrt(np.sum(kernel**2))
        b = np.convolve(rng.standard_normal(n_bins + w), np.ones(w) / np.sqrt(w), mode="valid")[: n_bins]
        err.append(0.8 * a + 0.6 * b)
    err = np.array(err)
    for level in (10.0, 40.0):
        k = int(level / 0.25)
        means = err[:, : n_bins // k * k].reshape(reps, -1, k).mean(axis=2)
        _, s = segment_sd(bins, np.ones(n_bins), level, shared=np.full(n_bins, 0.6))
        assert np.median(s) == pytest.approx(means.std(), rel=0.1)


def test_aggregate_profile_uses_the_shared_part():
    import pandas as pd

    from app.analysis.aggregate import aggregate_profile

    rng = np.random.default_rng(7)
    bins = np.arange(0, 400)
    sd = rng.uniform(0.1, 0.2, 400)
    df = pd.DataFrame({"bin": bins, "sleeper_amp_sd": sd, "sleeper_amp_sd_shared": 0.5 * sd})
    out = aggregate_profile(df, 10.0, ["sleeper_amp_sd", "sleeper_amp_sd_shared"])
    _, want = segment_sd(bins, sd, 10.0, shared=0.5 * sd)
    _, want_shared = segment_sd(bins, 0.5 * sd, 10.0, shared=0.5 * sd)
    np.testing.assert_allclose(out["sleeper_amp_sd_mean"], want)
    np.testing.assert_allclose(out["sleeper_amp_sd_shared_mean"], want_shared)
    assert np.all(out["sleeper_amp_sd_shared_mean"] < out["sleeper_amp_sd_mean"])
