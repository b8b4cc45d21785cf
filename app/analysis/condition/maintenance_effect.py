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

**Sign convention**: every change is *after − before* in ln units of the amplitude (its per cent:
``100 · expm1``); negative = the amplitude dropped.

**At matched speed** (``speeds`` given; issue 33): on a line run at more than one speed the extent's
index depends on the speed it was passed at, and a median over a window mixes the speed groups in the
proportions the window happens to hold, so the recovery reads the speed mix as well (measured on the
real-line bench: a tamping of −20 % read −10.6 %). Each run after the action is then compared with the
runs before it passed at its own speed (the matched-speed rule, :mod:`app.analysis.speed_match`) — by its
own vehicle where those hold any (``vehicles`` given: on rough rails the rails' response differs by vehicle
as it does by speed; the real line's grinding read +8.3 % on the support with the vehicles mixed, +2.4 %
matched) —: the extent's own baseline at that pass; the recovery is the median of those differences
(:func:`matched_change`).

**Interval**: ``recovery_low`` / ``recovery_high`` = recovery ∓ 1 σ (≈ 68 %), σ of the median
difference from the runs' own scatter about their baselines, pooled over both sides (``s`` = 1.4826 ·
MAD of the before-runs about their matched-speed baseline and of the after-runs' differences about
their median; a window of two runs, a baseline of one run, states no scatter of its own) and the median's √(π/2) efficiency:
``σ² = (π/2) · s² · (1 / n_after + 1 / n_before)``, ``n_before`` the before-runs at an after-run's speed
(median over the after-runs).

**How long it lasted** is said only within the data: ``lasted_days_projected`` is dropped where it
lies beyond the last run after the action (``followed_days``), the effect then still held as far as
the runs saw.

**By action type** (:func:`split_effect`). A tamping (any action on the support) changes the support:
its ``support_change`` is the recovery. A grinding or a rail renewal
(:data:`~app.analysis.condition.interventions.RAIL_SURFACE_ACTIONS`) changes the rails' running surface,
hence their roughness response in the sleeper order's band: the recovery across it is the **rail
surface's response** change (``rail_surface_change``), which the amplitude cannot tell from a change of
the support made the same day, so the support's change is read against the new surface's own baseline
instead: the runs after the ``after_days`` window against the runs inside it, at matched speed
(``support_change``; ≈ 0 where the work did not touch the support).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import paired_1d
from app.analysis.condition.interventions import RAIL_SURFACE_ACTIONS
from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE, speeds_matched
from app.analysis.units import DAYS_PER_YEAR

__all__ = ["ActionEffect", "SplitEffect", "action_effect", "matched_change", "split_effect"]

#: 1.4826 · MAD estimates σ of normal scatter.
_MAD_SIGMA = 1.4826


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
        The same projected from ``slope_after_per_year``; None where it lies beyond ``followed_days``.
    recovery_sigma : float or None
        1 σ of ``recovery`` (module docstring, "Interval").
    followed_days : float or None
        Days from the action to the last run after it (None: no run after it).
    """

    n_before: int
    n_after: int
    index_before: float | None
    index_after: float | None
    recovery: float | None
    slope_after_per_year: float | None
    lasted_days_observed: float | None
    lasted_days_projected: float | None
    recovery_sigma: float | None = None
    followed_days: float | None = None

    @property
    def recovery_low(self) -> float | None:
        """``recovery − recovery_sigma`` (ln units)."""
        return None if self.recovery is None or self.recovery_sigma is None else self.recovery - self.recovery_sigma

    @property
    def recovery_high(self) -> float | None:
        """``recovery + recovery_sigma`` (ln units)."""
        return None if self.recovery is None or self.recovery_sigma is None else self.recovery + self.recovery_sigma


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
    vehicles: np.ndarray | None = None,
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
        Speed of each run over the extent, m/s: the recovery at matched speed (:func:`matched_change`).
    speed_tolerance : float
        Of the matched-speed rule (> 0).
    vehicles : numpy.ndarray, optional
        Vehicle of each run (None: not stated): an after-run is compared with the before-runs of its own
        vehicle at its speed, where there are any (:func:`matched_change`).

    Returns
    -------
    ActionEffect
    """
    t, y = paired_1d(days, values, "days, values")
    vel = paired_1d(days, speeds, "days, speeds")[1] if speeds is not None else np.ones_like(t)
    veh = _vehicles(vehicles, t.size)
    for name, v in (("before_days", before_days), ("after_days", after_days), ("follow_days", follow_days)):
        if not v > 0:
            raise ValueError(f"{name}: must be > 0, got {v!r}")
    if not 0 < regain_fraction <= 1:
        raise ValueError(f"regain_fraction: must be in (0, 1], got {regain_fraction!r}")
    if rolling < 1 or min_runs < 1:
        raise ValueError("rolling, min_runs: must be >= 1")
    ok = np.isfinite(t) & np.isfinite(y)
    order = np.argsort(t[ok], kind="stable")
    t, y, vel, veh = t[ok][order], y[ok][order], vel[ok][order], veh[ok][order]
    followed = float(t[-1] - action_day) if t.size and t[-1] > action_day else None
    before = (t >= action_day - before_days) & (t < action_day)
    after = (t > action_day) & (t <= action_day + after_days)
    follow = (t > action_day) & (t <= action_day + follow_days)
    n_b, n_a = int(before.sum()), int(after.sum())
    if n_b < min_runs or n_a < min_runs:
        return ActionEffect(n_b, n_a, _f(np.median(y[before])) if n_b else None,
                            _f(np.median(y[after])) if n_a else None, None, None, None, None, None, followed)
    ib, ia = float(np.median(y[before])), float(np.median(y[after]))
    matched = _matched(y[before], vel[before], y[after], vel[after], speed_tolerance, veh[before], veh[after])
    if matched is None:
        return ActionEffect(n_b, n_a, ib, ia, None, None, None, None, None, followed)
    recovery, sigma = matched
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
        if followed is None or projected > followed:  # not beyond the runs seen
            projected = None
    return ActionEffect(n_b, n_a, ib, ia, recovery, slope, observed, projected, sigma, followed)


def _f(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _vehicles(vehicles: np.ndarray | None, n: int) -> np.ndarray:
    """The runs' vehicle labels as an object array (all None where not given)."""
    if vehicles is None:
        return np.full(n, None, dtype=object)
    g = np.asarray(vehicles, dtype=object)
    if g.shape != (n,):
        raise ValueError(f"vehicles: must have one label per run ({n}), got shape {g.shape}")
    return g


def _baseline(vb: np.ndarray, gb: np.ndarray, v: float, g: object, tolerance: float) -> np.ndarray:
    """The before-runs a run of speed ``v`` and vehicle ``g`` is compared with: those at its speed, of its own
    vehicle where there are any (the flags' and the places' matched passes, :mod:`app.analysis.speed_match`)."""
    m = speeds_matched(vb, v, tolerance)
    if g is not None:
        own = m & (gb == g)
        if own.any():
            return own
    return m


def _matched(yb: np.ndarray, vb: np.ndarray, ya: np.ndarray, va: np.ndarray, tolerance: float,
             gb: np.ndarray | None = None, ga: np.ndarray | None = None) -> tuple[float, float] | None:
    """(change, its 1 σ) of the after-values against the before-values at matched speed, of the same vehicle
    where the before-values hold some (None: no pair)."""
    gb = _vehicles(gb, yb.size)
    ga = _vehicles(ga, ya.size)
    okb = np.isfinite(yb) & np.isfinite(vb)
    yb, vb, gb = yb[okb], vb[okb], gb[okb]
    diffs, resid_b, n_base = [], [], []
    for y, v, g in zip(ya.tolist(), va.tolist(), ga.tolist(), strict=True):
        if not (np.isfinite(y) and np.isfinite(v)):
            continue
        m = _baseline(vb, gb, v, g, tolerance)
        if m.any():
            diffs.append(y - float(np.median(yb[m])))
            n_base.append(int(m.sum()))
    if not diffs:
        return None
    for v, g in zip(vb.tolist(), gb.tolist(), strict=True):  # each before-value about its own baseline
        m = _baseline(vb, gb, v, g, tolerance)
        if m.sum() >= 2:  # a baseline of one run is that run: no scatter of its own
            resid_b.append(yb[m] - np.median(yb[m]))
    d = np.asarray(diffs)
    change = float(np.median(d))
    rb = np.concatenate(resid_b) if resid_b else np.zeros(0)
    # one scatter of a run about its baseline, pooled over both sides (a window of 2 runs states none)
    s = _MAD_SIGMA * float(np.median(np.abs(np.concatenate([d - change, rb]))))
    # the before-runs an after-run is compared with: those at its speed
    sigma = float(s * np.sqrt(np.pi / 2.0 * (1.0 / d.size + 1.0 / float(np.median(n_base)))))
    return change, sigma


def matched_change(before: np.ndarray, before_speed: np.ndarray, after: np.ndarray, after_speed: np.ndarray, *,
                   tolerance: float = DEFAULT_SPEED_TOLERANCE, before_vehicle: np.ndarray | None = None,
                   after_vehicle: np.ndarray | None = None) -> float | None:
    """The change from ``before`` to ``after`` at matched passes: the median over the after-values of each one
    less the median of the before-values passed at its speed (its baseline at that speed) — by its own vehicle
    where the before-values hold any (on rough rails the rails' response differs by vehicle as by speed).

    Parameters
    ----------
    before, before_speed, after, after_speed : numpy.ndarray
        Values (ln units) and speeds (m/s) of the runs on either side.
    tolerance : float
        Of the matched-speed rule (:func:`~app.analysis.speed_match.speeds_matched`).
    before_vehicle, after_vehicle : numpy.ndarray, optional
        Vehicle of each run on either side (None: not stated).

    Returns
    -------
    float or None
        ln units; None where no after-value has a before-value at its speed.
    """
    yb, vb = paired_1d(before, before_speed, "before, before_speed")
    ya, va = paired_1d(after, after_speed, "after, after_speed")
    got = _matched(yb, vb, ya, va, tolerance, before_vehicle, after_vehicle)
    return None if got is None else got[0]


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
    support_sigma : float or None
        1 σ of ``support_change`` (module docstring, "Interval").
    """

    support_change: float | None
    rail_surface_change: float | None
    rail_surface: bool
    support_sigma: float | None = None

    @property
    def support_low(self) -> float | None:
        """``support_change − support_sigma`` (ln units)."""
        c, s = self.support_change, self.support_sigma
        return None if c is None or s is None else c - s

    @property
    def support_high(self) -> float | None:
        """``support_change + support_sigma`` (ln units)."""
        c, s = self.support_change, self.support_sigma
        return None if c is None or s is None else c + s


def split_effect(kind: str, days: np.ndarray, values: np.ndarray, speeds: np.ndarray, action_day: float,
                 effect: ActionEffect, *, after_days: float = 30.0, follow_days: float = 365.0,
                 speed_tolerance: float = DEFAULT_SPEED_TOLERANCE, min_runs: int = 2,
                 vehicles: np.ndarray | None = None) -> SplitEffect:
    """The effect on the support and on the rail surface's response of an action of type ``kind`` (module
    docstring, "By action type"), from the runs of :func:`action_effect` (``days``, ``values``, ``speeds``,
    ``vehicles``: its arguments) and its ``effect``."""
    if kind not in RAIL_SURFACE_ACTIONS:
        return SplitEffect(effect.recovery, None, False, effect.recovery_sigma)
    t, y = paired_1d(days, values, "days, values")
    v = paired_1d(days, speeds, "days, speeds")[1]
    g = _vehicles(vehicles, t.size)
    first = (t > action_day) & (t <= action_day + after_days)
    later = (t > action_day + after_days) & (t <= action_day + follow_days)
    got = None
    if first.sum() >= min_runs and later.sum() >= min_runs:
        got = _matched(y[first], v[first], y[later], v[later], speed_tolerance, g[first], g[later])
    return SplitEffect(None if got is None else got[0], effect.recovery, True, None if got is None else got[1])
