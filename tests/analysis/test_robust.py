"""The robust spread in one place (app.analysis.robust): 1.4826 · MAD, NaN ignored."""

from __future__ import annotations

import math

import numpy as np

from app.analysis.robust import MAD_TO_SD, mad_sd, robust_spread


def test_mad_sd_is_the_normal_consistent_mad_of_the_finite_values():
    rng = np.random.default_rng(5)
    x = rng.normal(3.0, 0.2, 20_000)
    assert abs(mad_sd(x) - 0.2) < 0.005
    with_gaps = np.r_[x[:100], np.nan, np.inf, x[100:200]]
    finite = np.r_[x[:100], x[100:200]]
    assert mad_sd(with_gaps) == MAD_TO_SD * np.median(np.abs(finite - np.median(finite)))
    assert math.isnan(mad_sd(np.array([np.nan, np.nan])))
    assert math.isnan(mad_sd(np.zeros(0)))


def test_one_history_spread_is_the_sample_spread_with_its_small_sample_correction():
    x = np.array([0.1, -0.3, 0.25, 0.0, 0.4, -0.1, 0.05, 0.2])
    _, spread = robust_spread(x[None, :])
    n = x.size
    assert spread[0] == mad_sd(x) * n / (n - 0.8)


def test_mad_sd_along_an_axis_ignores_nan_and_takes_a_known_centre():
    a = np.array([[1.0, 2.0, np.nan, 4.0, 100.0], [np.nan] * 5, [3.0, 3.0, 3.0, 3.0, 3.0]])
    out = mad_sd(a, axis=1)
    assert out[0] == MAD_TO_SD * 1.5  # median 3, |x - 3|: 2 1 1 97 -> 1.5
    assert math.isnan(out[1]) and out[2] == 0.0
    assert mad_sd(a[0], center=3.0) == out[0] == mad_sd(a[0])
    np.testing.assert_array_equal(mad_sd(a.T, axis=0), out)
    assert mad_sd(np.array([-np.inf, 1.0, 2.0, 3.0])) == MAD_TO_SD * 1.0  # ±inf: no value
