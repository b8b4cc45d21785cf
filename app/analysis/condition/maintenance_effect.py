"""The effect of a maintenance action on the condition index over its extent.

Input: the index over the action's extent per run (mean over its segments and
the wheels) and the runs' times. Around the action's day:

* ``index_before`` — median of the runs within ``before_days`` before it;
* ``index_after`` — median of the runs within ``after_days`` after it (the
  day itself excluded: the run may have been before the work);
* ``recovery = index_after − index_before`` (log units; negative: the index,
  e.g. the amplitude, dropped — the track was improved);
* ``slope_after_per_year`` — least-squares slope of the runs within
  ``follow_days`` after it;
* how long it lasted: the days until ``regain_fraction`` of the recovery is
  lost again — ``lasted_days_observed`` where a rolling median (``rolling`` runs)
  crossed that level, ``lasted_days_projected`` from the slope after (None when
  the index does not move back).

A recovery is reported only with runs on both sides (``min_runs`` each).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import paired_1d
from app.analysis.units import DAYS_PER_YEAR

__all__ = ["ActionEffect", "action_effect"]



@dataclass(frozen=True)
class ActionEffect:
    """Index before and after a maintenance action and how long the recovery lasted.

    Attributes
    ----------
    n_before, n_after : int
        Runs in the before and after windows.
    index_before, index_after, recovery : float or None
        Medians (log units) and their difference (None without runs on both sides).
    slope_after_per_year : float or None
        Index change per year after the action.
    lasted_days_observed : float or None
        Days from the action until the rolling median regained ``regain_fraction`` of the recovery.
    lasted_days_projected : float or None
        The same projected from ``slope_after_per_year``.
    """

    n_before: int
    n_after: int
    index_before: float | None
    index_after: float | None
    recovery: float | None
    slope_after_per_year: float | None
    lasted_days_observed: float | None
    lasted_days_projected: float | None


def action_effect(
    days: np.ndarray,
    values: np.ndarray,
    action_day: float,
    *,
    before_days: float = 90.0,
    after_days: float = 30.0,
    follow_days: float = 365.0,
    regain_fraction: float = 0.5,
    rolling: int = 5,
    min_runs: int = 2,
) -> ActionEffect:
    """Effect of an action on day ``action_day`` (see the module docstring).

    Parameters
    ----------
    days, values : numpy.ndarray
        Time of each run (days) and its index over the action's extent (NaN: none).
    action_day : float
        Day of the action (same axis).
    before_days, after_days, follow_days : float
        Windows before, just after and for the slope after, days (> 0).
    regain_fraction : float
        Fraction of the recovery whose loss ends the effect, in (0, 1].
    rolling : int
        Runs of the rolling median for the observed end (>= 1).
    min_runs : int
        Fewest runs a window needs (>= 1).

    Returns
    -------
    ActionEffect
    """
    t, y = paired_1d(days, values, "days, values")
    for name, v in (("before_days", before_days), ("after_days", after_days), ("follow_days", follow_days)):
        if not v > 0:
            raise ValueError(f"{name}: must be > 0, got {v!r}")
    if not 0 < regain_fraction <= 1:
        raise ValueError(f"regain_fraction: must be in (0, 1], got {regain_fraction!r}")
    if rolling < 1 or min_runs < 1:
        raise ValueError("rolling, min_runs: must be >= 1")
    ok = np.isfinite(t) & np.isfinite(y)
    order = np.argsort(t[ok], kind="stable")
    t, y = t[ok][order], y[ok][order]
    before = (t >= action_day - before_days) & (t < action_day)
    after = (t > action_day) & (t <= action_day + after_days)
    follow = (t > action_day) & (t <= action_day + follow_days)
    n_b, n_a = int(before.sum()), int(after.sum())
    if n_b < min_runs or n_a < min_runs:
        return ActionEffect(n_b, n_a, _f(np.median(y[before])) if n_b else None,
                            _f(np.median(y[after])) if n_a else None, None, None, None, None)
    ib, ia = float(np.median(y[before])), float(np.median(y[after]))
    recovery = ia - ib
    slope = None
    if follow.sum() >= 3 and np.ptp(t[follow]) > 0:
        slope = float(np.polyfit(t[follow], y[follow], 1)[0] * DAYS_PER_YEAR)
    target = ia - regain_fraction * recovery  # the level where the given fraction is lost again
    observed = None
    post = np.flatnonzero(t > action_day)
    if post.size >= rolling and recovery != 0:
        med = np.array([np.median(y[post[max(k - rolling + 1, 0): k + 1]]) for k in range(post.size)])
        back = (med >= target) if recovery < 0 else (med <= target)
        back[: rolling - 1] = False
        if back.any():
            observed = float(t[post[int(np.argmax(back))]] - action_day)
    projected = None
    if slope is not None and recovery != 0 and np.sign(slope) == -np.sign(recovery):
        projected = float(regain_fraction * abs(recovery) / abs(slope) * DAYS_PER_YEAR)
    return ActionEffect(n_b, n_a, ib, ia, recovery, slope, observed, projected)


def _f(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None
