"""Trend of a place and the time until it reaches a limit.

A place's severity over the runs that saw it (time in days, severity in ln
units) is fitted by ordinary least squares; the rate comes with its standard
error and a Student-t interval. The projected date of the next tier is given
only where the trend is **significant** (the interval excludes 0) and goes
**towards** the limit; its interval is the dates at the interval's ends of the
rate (the slower end may never reach it: no late date).

Ordinary least squares rather than a robust fit: a place's series is short
(its runs), the interval has its exact meaning under normal errors, and an
odd run shows as a wide interval (no projection) instead of being quietly
down-weighted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.analysis.units import DAYS_PER_YEAR

__all__ = ["Trend", "linear_trend", "Projection", "time_to_limit", "DAYS_PER_YEAR"]



@dataclass(frozen=True)
class Trend:
    """A least-squares line through a place's series.

    Attributes
    ----------
    rate_per_year : float
        Slope, units per year (NaN: too few points or no spread in time).
    se_per_year : float
        Its standard error, units per year.
    low_per_year, high_per_year : float
        The ``confidence`` interval of the slope.
    level : float
        The line's value at ``now_day`` (the last point's time unless given).
    n : int
        Points fitted.
    significant : bool
        The interval excludes 0.
    """

    rate_per_year: float
    se_per_year: float
    low_per_year: float
    high_per_year: float
    level: float
    n: int
    significant: bool


_NO_TREND = dict(rate_per_year=math.nan, se_per_year=math.nan, low_per_year=math.nan, high_per_year=math.nan,
                 significant=False)


def linear_trend(days: np.ndarray, values: np.ndarray, *, now_day: float | None = None,
                 confidence: float = 0.95, min_points: int = 3) -> Trend:
    """Fit ``value = level + rate · (day − now) / DAYS_PER_YEAR``.

    Parameters
    ----------
    days : numpy.ndarray
        Time of each point, days (any origin).
    values : numpy.ndarray
        Value of each point (NaN points are left out).
    now_day : float, optional
        Where ``level`` is evaluated, days (default the last finite point's time).
    confidence : float
        Two-sided level of the interval, in (0, 1).
    min_points : int
        Fewest points for a rate (≥ 3: two points have no error estimate).

    Returns
    -------
    Trend
    """
    t = np.asarray(days, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    if t.shape != y.shape or t.ndim != 1:
        raise ValueError("days, values: must be 1-D of equal length")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence: must be in (0, 1), got {confidence!r}")
    if min_points < 3:
        raise ValueError(f"min_points: must be >= 3, got {min_points!r}")
    ok = np.isfinite(t) & np.isfinite(y)
    t, y = t[ok], y[ok]
    n = int(t.size)
    if n == 0:
        return Trend(level=math.nan, n=0, **_NO_TREND)
    now = float(t[np.argmax(t)]) if now_day is None else float(now_day)
    if not math.isfinite(now):
        raise ValueError(f"now_day: must be finite, got {now_day!r}")
    tc = t - t.mean()
    sxx = float(np.sum(tc * tc))
    if n < min_points or sxx <= 0:
        return Trend(level=float(np.mean(y)), n=n, **_NO_TREND)
    slope = float(np.sum(tc * (y - y.mean())) / sxx)
    resid = y - y.mean() - slope * tc
    s2 = float(np.sum(resid * resid)) / (n - 2)
    se = math.sqrt(s2 / sxx)
    # here: the settings name this module's constants (a light import)
    from scipy.special import stdtrit

    q = float(stdtrit(n - 2, 0.5 + confidence / 2))  # Student's t quantile
    lo, hi = slope - q * se, slope + q * se
    level = float(y.mean() + slope * (now - t.mean()))
    significant = bool(se > 0 and (lo > 0 or hi < 0)) or bool(se == 0 and slope != 0)
    return Trend(rate_per_year=slope * DAYS_PER_YEAR, se_per_year=se * DAYS_PER_YEAR, low_per_year=lo * DAYS_PER_YEAR,
                 high_per_year=hi * DAYS_PER_YEAR, level=level, n=n, significant=significant)


@dataclass(frozen=True)
class Projection:
    """When a growing severity reaches a limit (days from the trend's ``now``; NaN: not projected).

    Attributes
    ----------
    days, days_early, days_late : float
        At the fitted rate, at the interval's fast end and at its slow end
        (``inf`` when the slow end does not grow).
    """

    days: float
    days_early: float
    days_late: float


def time_to_limit(trend: Trend, limit: float) -> Projection:
    """Days until the severity's trend line reaches ``limit``.

    Parameters
    ----------
    trend : Trend
        Of the severity (ln units; growing = positive rate).
    limit : float
        The next tier's limit (NaN: none above).

    Returns
    -------
    Projection
        NaN unless the trend is significant, grows and the limit lies above its level
        (0 days when the line is already at or beyond it).
    """
    nan = Projection(math.nan, math.nan, math.nan)
    if not (math.isfinite(limit) and trend.significant and trend.rate_per_year > 0 and math.isfinite(trend.level)):
        return nan
    gap = max(limit - trend.level, 0.0)
    days = gap / trend.rate_per_year * DAYS_PER_YEAR
    early = gap / trend.high_per_year * DAYS_PER_YEAR
    late = gap / trend.low_per_year * DAYS_PER_YEAR if trend.low_per_year > 0 else math.inf
    return Projection(days, early, late)
