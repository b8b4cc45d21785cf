"""Straight-line least squares with autocorrelation-aware confidence intervals.

Profiles along the track are strongly autocorrelated (the VKF smooths the
amplitude over tens of metres; stiffness varies over similar lengths), so the
textbook OLS standard errors of a fit over thousands of 25 cm bins are far too
narrow. :func:`linear_fit` therefore estimates the covariance of the
coefficients with the Newey–West (Bartlett kernel) HAC estimator over
neighbouring samples of the same series (``groups``), and the confidence
intervals use the normal quantile.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr, ndtri  # scipy.stats' norm without its import (≈ 1 s per process)

__all__ = ["LinearFit", "linear_fit", "decimate_indices"]


@dataclass(frozen=True)
class LinearFit:
    """Result of ``y = slope * x + intercept``.

    Attributes
    ----------
    slope, intercept : float
        Least-squares coefficients (units of y per unit of x, units of y).
    slope_ci, intercept_ci : tuple of float
        Confidence intervals (HAC standard errors, normal quantile).
    slope_se, intercept_se : float
        Their standard errors.
    rmse : float
        Standard deviation of the residuals (ddof = 2), units of y.
    r2, r : float
        Coefficient of determination and Pearson correlation.
    p_value : float
        Two-sided p-value of ``slope == 0`` (HAC standard error).
    n : int
        Number of samples.
    hac_lag : int
        Lag (samples) of the Newey–West estimator; 0 = heteroscedasticity-robust only.
    confidence : float
        Level of the intervals.
    """

    slope: float
    intercept: float
    slope_ci: tuple[float, float]
    intercept_ci: tuple[float, float]
    slope_se: float
    intercept_se: float
    rmse: float
    r2: float
    r: float
    p_value: float
    n: int
    hac_lag: int
    confidence: float


def _nan_fit(n: int, lag: int, confidence: float) -> LinearFit:
    nan = float("nan")
    return LinearFit(nan, nan, (nan, nan), (nan, nan), nan, nan, nan, nan, nan, nan, n, lag, confidence)


def _series_bounds(groups: np.ndarray | None, n: int) -> list[tuple[int, int]]:
    if groups is None:
        return [(0, n)]
    cut = np.flatnonzero(groups[1:] != groups[:-1]) + 1
    edges = np.r_[0, cut, n]
    return list(zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True))


def _hac_meat(u: np.ndarray, groups: np.ndarray | None, lag: int) -> np.ndarray:
    """Newey–West ``S = G_0 + sum_k w_k (G_k + G_k^T)`` of ``u`` (p, n) within each series.

    Lagged products ``G_k = sum_t u_t u_{t-k}^T`` come from FFT cross-correlations.
    """
    p, n = u.shape
    s = u @ u.T
    if lag == 0:
        return s
    w = 1.0 - np.arange(1, lag + 1) / (lag + 1.0)
    for a, b in _series_bounds(groups, n):
        m = b - a
        if m < 2:
            continue
        k = min(lag, m - 1)
        nfft = 1 << int(np.ceil(np.log2(2 * m)))
        f = np.fft.rfft(u[:, a:b], n=nfft)
        for i in range(p):
            for j in range(p):
                c = np.fft.irfft(f[i] * np.conj(f[j]), n=nfft)[1: k + 1]  # sum_t u_i[t+k] u_j[t]
                g = float(w[:k] @ c)
                s[i, j] += g
                s[j, i] += g
    return s


def linear_fit(
    x: np.ndarray,
    y: np.ndarray,
    *,
    groups: np.ndarray | None = None,
    hac_lag: int = 0,
    confidence: float = 0.95,
) -> LinearFit:
    """Fit ``y = slope * x + intercept`` by least squares.

    Parameters
    ----------
    x, y : numpy.ndarray
        Samples (1-D, equal length, finite). Samples of one series must be
        consecutive and in track order for the HAC estimator to be meaningful.
    groups : numpy.ndarray, optional
        Series label per sample (e.g. run and wheel); lagged products are only
        formed within a series. Default: one series.
    hac_lag : int
        Newey–West lag in samples (>= 0); choose about the correlation length
        of the residuals (e.g. 100 m / 0.25 m = 400 bins).
    confidence : float
        Level of the confidence intervals, in (0, 1).

    Returns
    -------
    LinearFit
        All-NaN statistics (with ``n``) when fewer than 3 samples or no spread in x.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 1 or y.shape != x.shape:
        raise ValueError(f"x, y: must be 1-D of equal length, got {x.shape} and {y.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("x, y: must be finite")
    if int(hac_lag) != hac_lag or hac_lag < 0:
        raise ValueError(f"hac_lag: must be an integer >= 0, got {hac_lag!r}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence: must be in (0, 1), got {confidence!r}")
    if groups is not None:
        groups = np.asarray(groups)
        if groups.shape != x.shape:
            raise ValueError(f"groups: must have the shape of x {x.shape}, got {groups.shape}")
    n = x.size
    lag = int(hac_lag)
    if n < 3 or np.ptp(x) == 0:
        return _nan_fit(n, lag, confidence)
    xm, ym = x.mean(), y.mean()
    dx, dy = x - xm, y - ym
    sxx = float(dx @ dx)
    slope = float(dx @ dy) / sxx
    intercept = ym - slope * xm
    resid = y - (slope * x + intercept)
    sse = float(resid @ resid)
    syy = float(dy @ dy)
    rmse = math.sqrt(sse / (n - 2))
    r2 = 1.0 - sse / syy if syy > 0 else float("nan")
    r = float(np.corrcoef(x, y)[0, 1]) if syy > 0 else float("nan")

    # HAC covariance of (intercept, slope): (X'X)^-1 S (X'X)^-1, S over u_t = x_t e_t
    s = _hac_meat(np.stack([resid, x * resid]), groups, lag)
    xtx = np.array([[n, x.sum()], [x.sum(), float(x @ x)]])
    inv = np.linalg.inv(xtx)
    cov = inv @ s @ inv * (n / (n - 2))
    se_b, se_a = math.sqrt(max(cov[0, 0], 0.0)), math.sqrt(max(cov[1, 1], 0.0))
    z = float(ndtri(0.5 + confidence / 2))
    p = float(2 * ndtr(-abs(slope) / se_a)) if se_a > 0 else 0.0
    return LinearFit(
        slope=slope,
        intercept=float(intercept),
        slope_ci=(slope - z * se_a, slope + z * se_a),
        intercept_ci=(float(intercept) - z * se_b, float(intercept) + z * se_b),
        slope_se=se_a,
        intercept_se=se_b,
        rmse=rmse,
        r2=float(r2),
        r=r,
        p_value=p,
        n=n,
        hac_lag=lag,
        confidence=confidence,
    )


def decimate_indices(n: int, max_points: int) -> np.ndarray:
    """Evenly spread indices of at most ``max_points`` of ``n`` samples (all when ``n`` fits)."""
    if n < 0 or max_points < 1:
        raise ValueError(f"n must be >= 0 and max_points >= 1, got {n}, {max_points}")
    if n <= max_points:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_points).round().astype(np.int64))
