"""Maintenance actions per 25 cm bin against the sleeper-passage amplitude (paper, Fig. 6)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import paired_1d
from app.analysis.stiffness.regression import LinearFit, linear_fit

__all__ = ["BoxStats", "MaintenanceCorrelation", "count_actions", "box_stats", "maintenance_correlation"]


@dataclass(frozen=True)
class BoxStats:
    """Box-plot statistics of the amplitude of the bins with ``n_actions`` actions (m/s²).

    Whiskers reach the most extreme values within 1.5 IQR of the quartiles.
    """

    n_actions: int
    n_bins: int
    q1: float
    median: float
    q3: float
    whisker_low: float
    whisker_high: float
    mean: float


@dataclass(frozen=True)
class MaintenanceCorrelation:
    """Box plots per number of actions and the regression ``amplitude = slope n + intercept``."""

    groups: list[BoxStats]
    regression: LinearFit


def count_actions(position_m: np.ndarray, start_m: np.ndarray, end_m: np.ndarray) -> np.ndarray:
    """Number of actions ``[start_m, end_m]`` covering each position.

    Parameters
    ----------
    position_m : numpy.ndarray
        Positions (bin centres) on the km axis, m.
    start_m, end_m : numpy.ndarray
        Extent of each action, m (``start_m <= end_m``; inclusive).

    Returns
    -------
    numpy.ndarray
        int64 counts per position.
    """
    x = np.asarray(position_m, dtype=np.float64)
    a, b = paired_1d(start_m, end_m, "start_m, end_m")
    if np.any(a > b):
        raise ValueError("start_m, end_m: every action needs start_m <= end_m")
    started = np.searchsorted(np.sort(a), x, side="right")
    ended = np.searchsorted(np.sort(b), x, side="left")
    return (started - ended).astype(np.int64)


def box_stats(n_actions: int, values: np.ndarray) -> BoxStats:
    """Box-plot statistics of ``values`` (finite, non-empty)."""
    v = np.sort(np.asarray(values, dtype=np.float64))
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise ValueError("values: must be non-empty and finite")
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    iqr = q3 - q1
    lo = v[v >= q1 - 1.5 * iqr][0]
    hi = v[v <= q3 + 1.5 * iqr][-1]
    return BoxStats(int(n_actions), int(v.size), float(q1), float(med), float(q3), float(lo), float(hi), float(v.mean()))


def maintenance_correlation(
    amplitude: np.ndarray,
    counts: np.ndarray,
    *,
    groups: np.ndarray | None = None,
    hac_lag: int = 400,
) -> MaintenanceCorrelation:
    """Box plots of the amplitude per number of actions and its linear regression on the count.

    Parameters
    ----------
    amplitude : numpy.ndarray
        Sleeper-passage amplitude per bin, m/s² (finite).
    counts : numpy.ndarray
        Number of maintenance actions per bin (integers >= 0).
    groups : numpy.ndarray, optional
        Series label per sample (consecutive bins of a stretch in km order).
    hac_lag : int
        Newey–West lag in bins for the p-value (default 400 = 100 m).
    """
    amplitude = np.asarray(amplitude, dtype=np.float64)
    counts = np.asarray(counts)
    if counts.shape != amplitude.shape:
        raise ValueError("amplitude, counts: must have equal shapes")
    if counts.size and (np.any(counts < 0) or np.any(counts != np.round(counts))):
        raise ValueError("counts: must be integers >= 0")
    groups_out = [box_stats(int(k), amplitude[counts == k]) for k in np.unique(counts)]
    fit = linear_fit(counts.astype(np.float64), amplitude, groups=groups, hac_lag=hac_lag)
    return MaintenanceCorrelation(groups_out, fit)
