"""Subsidence model ``u = a ln(Z) + b`` (paper, table tab:01).

``Z`` is the sleeper-passage acceleration amplitude of one wheel in m/s²
(the logarithm is the natural one, of ``Z / (1 m/s²)``), ``u`` the subsidence
in mm as the subsidence vehicle reports it (negative = down), per 25 cm bin.
"""

from __future__ import annotations

import numpy as np

from app.analysis._checks import check_positive, paired_1d
from app.analysis.stiffness.regression import LinearFit, linear_fit

__all__ = ["LOG_BASE", "bin_means", "fit_subsidence", "predict_subsidence"]

#: Base of the logarithm in ``u = a log(Z) + b``.
LOG_BASE = "e"


def bin_means(position_m: np.ndarray, values: np.ndarray, bin_length_m: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``values`` per bin ``floor(position_m / bin_length_m)``.

    Parameters
    ----------
    position_m : numpy.ndarray
        Positions on the km axis, m (``1000 * km``).
    values : numpy.ndarray
        Values at those positions (non-finite ones are ignored).
    bin_length_m : float
        Bin length, m (> 0).

    Returns
    -------
    bins : numpy.ndarray
        Sorted bin indices (int64) with at least one finite value.
    means : numpy.ndarray
        Mean value per bin.
    """
    position_m, values = paired_1d(position_m, values, "position_m, values")
    check_positive(bin_length_m, "bin_length_m")
    ok = np.isfinite(position_m) & np.isfinite(values)
    b = np.floor(position_m[ok] / bin_length_m).astype(np.int64)
    uniq, inv = np.unique(b, return_inverse=True)
    sums = np.bincount(inv, weights=values[ok], minlength=uniq.size)
    counts = np.bincount(inv, minlength=uniq.size)
    return uniq, sums / np.maximum(counts, 1)


def fit_subsidence(
    amplitude: np.ndarray,
    subsidence_mm: np.ndarray,
    *,
    groups: np.ndarray | None = None,
    hac_lag: int = 400,
    confidence: float = 0.95,
) -> LinearFit:
    """Fit ``u = a ln(Z) + b`` over paired bins.

    Parameters
    ----------
    amplitude : numpy.ndarray
        Sleeper-passage acceleration amplitude ``Z`` per bin, m/s² (> 0).
    subsidence_mm : numpy.ndarray
        Measured subsidence ``u`` in the same bins, mm.
    groups : numpy.ndarray, optional
        Series label per sample (run); samples of a series consecutive, in km order.
    hac_lag : int
        Newey–West lag in bins for the confidence intervals (default 400 = 100 m).
    confidence : float
        Level of the intervals.

    Returns
    -------
    LinearFit
        ``slope`` = a (mm per unit of ln), ``intercept`` = b (mm), ``rmse`` (mm).
    """
    amplitude = np.asarray(amplitude, dtype=np.float64)
    if np.any(~(amplitude > 0)):
        raise ValueError("amplitude: must be > 0 m/s² (log model)")
    return linear_fit(
        np.log(amplitude), np.asarray(subsidence_mm, dtype=np.float64),
        groups=groups, hac_lag=hac_lag, confidence=confidence,
    )


def predict_subsidence(amplitude: np.ndarray, slope: float, intercept: float) -> np.ndarray:
    """Predicted subsidence ``a ln(Z) + b`` in mm; NaN where ``Z`` is not > 0.

    Parameters
    ----------
    amplitude : numpy.ndarray
        ``Z``, m/s².
    slope, intercept : float
        ``a`` (mm per unit of ln) and ``b`` (mm).
    """
    z = np.asarray(amplitude, dtype=np.float64)
    out = np.full(z.shape, np.nan)
    ok = z > 0
    out[ok] = slope * np.log(z[ok]) + intercept
    return out
