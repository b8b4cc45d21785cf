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

**At matched speed** (``speeds`` given; issue 33): on a line run at more than one speed the extent's
index depends on the speed it was passed at, and a median over a window mixes the speed groups in the
proportions the window happens to hold — the recovery then reads the speed mix as well (measured: a
tamping of −20 % read −10.6 %). Each run after the action is then compared with the runs before it
at its own speed (the matched-speed rule, :mod:`app.analysis.speed_match`): the extent's own baseline
at that speed; the recovery is the median of those differences.

**By action type.** A tamping (any action on the support) changes the support: its ``support_change``
is the recovery. A grinding or a rail renewal (:data:`~app.analysis.condition.interventions.RAIL_SURFACE_ACTIONS`)
changes the rails' running surface, hence their roughness response in the sleeper order's band: the
recovery across it is the **rail surface's response** change (``rail_surface_change``), which the
amplitude cannot tell from a change of the support made the same day — so the support's change is read
against the new surface's own baseline instead: the runs after the ``after_days`` window against the
runs inside it, at matched speed (``support_change``; ≈ 0 where the work did not touch the support).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import paired_1d
from app.analysis.condition.interventions import RAIL_SURFACE_ACTIONS
from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE, speeds_matched

__all__ = ["ActionEffect", "action_effect", "matched_change", "split_effect", "SplitEffect"]

_DAYS_PER_YEAR = 365.25


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
    speeds: np.ndarray | None = None,
    speed_tolerance: float = DEFAULT_SPEED_TOLERANCE,
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
    speeds : numpy.ndarray, optional
        Speed of each run over the extent (m/s): the recovery at matched speed (:func:`matched_change`).
    speed_tolerance : float
        Of the matched-speed rule.

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
    v = None
    if speeds is not None:
        _, v = paired_1d(days, speeds, "days, speeds")
    ok = np.isfinite(t) & np.isfinite(y)
    order = np.argsort(t[ok], kind="stable")
    t, y = t[ok][order], y[ok][order]
    if v is not None:
        v = v[ok][order]
    before = (t >= action_day - before_days) & (t < action_day)
    after = (t > action_day) & (t <= action_day + after_days)
    follow = (t > action_day) & (t <= action_day + follow_days)
    n_b, n_a = int(before.sum()), int(after.sum())
    if n_b < min_runs or n_a < min_runs:
        return ActionEffect(n_b, n_a, _f(np.median(y[before])) if n_b else None,
                            _f(np.median(y[after])) if n_a else None, None, None, None, None)
    ib, ia = float(np.median(y[before])), float(np.median(y[after]))
    recovery = ia - ib
    if v is not None:
        recovery = matched_change(y[before], v[before], y[after], v[after], tolerance=speed_tolerance)
        if recovery is None:
            return ActionEffect(n_b, n_a, ib, ia, None, None, None, None)
    slope = None
    if follow.sum() >= 3 and np.ptp(t[follow]) > 0:
        slope = float(np.polyfit(t[follow], y[follow], 1)[0] * _DAYS_PER_YEAR)
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
        projected = float(regain_fraction * abs(recovery) / abs(slope) * _DAYS_PER_YEAR)
    return ActionEffect(n_b, n_a, ib, ia, recovery, slope, observed, projected)


def _f(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def matched_change(before: np.ndarray, before_speed: np.ndarray, after: np.ndarray, after_speed: np.ndarray, *,
                   tolerance: float = DEFAULT_SPEED_TOLERANCE) -> float | None:
    """The change from ``before`` to ``after`` at matched speed: the median over the after-values of each one
    less the median of the before-values passed at its speed (its baseline at that speed).

    Parameters
    ----------
    before, before_speed, after, after_speed : numpy.ndarray
        Values (ln units) and speeds (m/s) of the runs on either side.
    tolerance : float
        Of the matched-speed rule (:func:`~app.analysis.speed_match.speeds_matched`).

    Returns
    -------
    float or None
        None where no after-value has a before-value at its speed.
    """
    yb, vb = paired_1d(before, before_speed, "before, before_speed")
    ya, va = paired_1d(after, after_speed, "after, after_speed")
    okb = np.isfinite(yb) & np.isfinite(vb)
    yb, vb = yb[okb], vb[okb]
    diffs = []
    for y, v in zip(ya, va, strict=True):
        if not (np.isfinite(y) and np.isfinite(v)):
            continue
        m = speeds_matched(vb, v, tolerance)
        if m.any():
            diffs.append(y - float(np.median(yb[m])))
    return float(np.median(diffs)) if diffs else None


@dataclass(frozen=True)
class SplitEffect:
    """What an action did to the support and to the rail surface's response, apart (ln units; None: not read).

    Attributes
    ----------
    support_change : float or None
        The support's change (a tamping: the recovery; a rail-surface action: the change since the work,
        against the new surface's own baseline).
    rail_surface_change : float or None
        The rail surface's response change across the action (a rail-surface action only; else None).
    rail_surface : bool
        The action changes the rails' running surface.
    """

    support_change: float | None
    rail_surface_change: float | None
    rail_surface: bool


def split_effect(kind: str, days: np.ndarray, values: np.ndarray, speeds: np.ndarray, action_day: float,
                 effect: ActionEffect, *, after_days: float = 30.0, follow_days: float = 365.0,
                 speed_tolerance: float = DEFAULT_SPEED_TOLERANCE, min_runs: int = 2) -> SplitEffect:
    """The effect on the support and on the rail surface's response of an action of type ``kind`` (module
    docstring, "By action type"), from the runs of :func:`action_effect` and its ``effect``."""
    if kind not in RAIL_SURFACE_ACTIONS:
        return SplitEffect(effect.recovery, None, False)
    t, y = paired_1d(days, values, "days, values")
    _, v = paired_1d(days, speeds, "days, speeds")
    first = (t > action_day) & (t <= action_day + after_days)
    later = (t > action_day + after_days) & (t <= action_day + follow_days)
    support = None
    if first.sum() >= min_runs and later.sum() >= min_runs:
        support = matched_change(y[first], v[first], y[later], v[later], tolerance=speed_tolerance)
    return SplitEffect(support, effect.recovery, True)
