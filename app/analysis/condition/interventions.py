"""Maintenance actions as the change tests see them: which actions change the rails' running surface
(a grinding, a rail renewal) — hence their roughness response, which the stated 1-σ of a pass is mostly
made of — and which the support (a tamping, ballast cleaning: every other type), how far beyond its
recorded extent an action changes the indicator, the day of the latest one on each segment, and a
history without the runs before it.

The change tests (:mod:`app.analysis.condition.change`) take the days: across a rail-surface action
both sides' roughness response enter a step's 1-σ and the trend leaves out the runs before it (its
docstring, "the rail surface changed"); an action on the support **starts the segment's history
anew** (:func:`since_actions`): the track before it is not the track after it, by intent, so a step or
a trend read across it measures the work, not the support developing (measured on the demo's history:
a place tamped two thirds back was listed a month later as an alert place "growing" softer at −174 %
a year, its trend fitted through the runs before the tamping and its step read against them)."""

from __future__ import annotations

import numpy as np

__all__ = ["RAIL_SURFACE_ACTIONS", "intervention_margin_m", "latest_action_days", "since_actions"]

#: Maintenance types (the reference import's ``type``) that change the rails' running surface, hence
#: their roughness response: grinding (and milling, recorded as grinding) and rail renewal.
RAIL_SURFACE_ACTIONS: tuple[str, ...] = ("grinding", "rail_replacement")


def intervention_margin_m(resolution_m: float = 3.0, filter_order: int = 2) -> float:
    """How far beyond a rail-surface intervention's recorded extent the indicator still changes, m: half
    the floor window (:func:`app.analysis.uncertainty.shared_window_m`, whose estimates mix both surfaces)
    plus the first zero of the envelope's correlation (:func:`app.analysis.uncertainty.correlation_zero`);
    14.2 m at 3 m resolution, q = 2."""
    # imported here: the lifecycle (and with it the settings) reads this module, and the uncertainty's scipy costs
    # every CLI command seconds (tests/core/test_settings_defaults.py)
    from app.analysis.uncertainty import correlation_zero, shared_window_m

    return shared_window_m(resolution_m, filter_order) / 2.0 + correlation_zero(resolution_m, filter_order)


def latest_action_days(
    seg: np.ndarray, segment_m: float, start_m: np.ndarray, end_m: np.ndarray, day: np.ndarray, now_days: float,
    margin_m: float | None = None,
) -> np.ndarray:
    """Day of the latest maintenance action on each segment up to ``now_days`` (NaN: none).

    Parameters
    ----------
    seg : numpy.ndarray
        (segments,) segment numbers (``[seg · segment_m, (seg + 1) · segment_m)``, m).
    segment_m : float
        Segment length, m (> 0).
    start_m, end_m, day : numpy.ndarray
        (actions,) extent (m, same axis) and day of each action (e.g. the maintenance records of
        :data:`RAIL_SURFACE_ACTIONS`, or of the other types).
    now_days : float
        Day of the newest run; later interventions do not count.
    margin_m : float, optional
        The extents are widened by this much on either side, m (default :func:`intervention_margin_m`).

    Returns
    -------
    numpy.ndarray
        (segments,) day, NaN where no action overlaps the segment.
    """
    if not (np.isfinite(segment_m) and segment_m > 0):
        raise ValueError(f"segment_m: must be > 0, got {segment_m!r}")
    s = np.asarray(seg, dtype=np.float64)
    a, b, d = (np.asarray(v, dtype=np.float64).reshape(-1) for v in (start_m, end_m, day))
    if not (a.shape == b.shape == d.shape):
        raise ValueError("start_m, end_m, day: must have one value per intervention")
    out = np.full(s.shape, np.nan)
    if s.size == 0 or a.size == 0:
        return out
    pad = intervention_margin_m() if margin_m is None else float(margin_m)
    if not (np.isfinite(pad) and pad >= 0):
        raise ValueError(f"margin_m: must be >= 0, got {margin_m!r}")
    lo, hi = s * segment_m, (s + 1) * segment_m
    for x0, x1, t in zip(np.minimum(a, b) - pad, np.maximum(a, b) + pad, d, strict=True):
        if not (np.isfinite(t) and t <= now_days):
            continue
        hit = (lo < x1) & (hi > x0)
        out[hit] = np.fmax(out[hit], t)
    return out


def since_actions(history: np.ndarray, history_days: np.ndarray, action_days: np.ndarray) -> np.ndarray:
    """A history without the runs before the latest action on the support of each segment (module docstring).

    Parameters
    ----------
    history : numpy.ndarray
        (..., segments, runs) values of the earlier runs (NaN: none), e.g. (wheels, segments, runs).
    history_days : numpy.ndarray
        (runs,) day of each history run.
    action_days : numpy.ndarray
        (segments,) day of the latest action on each segment (:func:`latest_action_days`; NaN: none).

    Returns
    -------
    numpy.ndarray
        ``history`` (float64) with NaN where a run predates its segment's action.
    """
    h = np.asarray(history, dtype=np.float64)
    t = np.asarray(history_days, dtype=np.float64).reshape(-1)
    a = np.asarray(action_days, dtype=np.float64).reshape(-1)
    if h.ndim < 2 or h.shape[-2:] != (a.size, t.size):
        raise ValueError(f"history: must end in (segments, runs) = ({a.size}, {t.size}), got shape {h.shape}")
    with np.errstate(invalid="ignore"):
        before = t[None, :] < a[:, None]  # NaN (no action): False
    return np.where(before, np.nan, h)
