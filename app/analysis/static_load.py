"""Static load out of a force channel: a moving mean over travelled distance, subtracted.

A wheel–rail force channel carries the static wheel load (tens of kN) under
the dynamic part the VKF extracts (about one kN at the sleeper passage). The
VKF rejects a constant far from an order's frequency over a long record, but
near a record's ends (the smoother sees one side only) and wherever the train
is slow (the orders close to 0 Hz) a part of it leaks into the envelopes:
before this step the sleeper-passage force amplitude was wrong by up to 12x
within the first ~17 m of a run. So the slowly varying mean is removed first.

The mean is a moving average over a window of travelled distance ``W``
rounded to a whole number of sleeper bays: a component periodic in distance
with the sleeper spacing (the sleeper passage and all its harmonics) averages
to exactly zero over it at any speed profile, so the mean holds none of the
indicator's content; a wheel order of wavelength ``λ = π d_w / l`` leaks into
it by at most ``λ / (π W)`` (order 1 of a 0.92 m wheel over 12 m: 8 %, only in
the force channel's wheel orders, which are not stored). At the record's ends
the window keeps its length and slides inside the record (no one-sided,
shorter average), so the mean is as good at the first metre as anywhere.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["bay_window_m", "moving_mean_over_distance", "remove_static_load"]


def bay_window_m(window_m: float, sleeper_spacing: float) -> float:
    """``window_m`` rounded to a whole number (≥ 1) of sleeper bays, m."""
    if not (math.isfinite(window_m) and window_m > 0):
        raise ValueError(f"window_m must be > 0 m, got {window_m!r}")
    if not (math.isfinite(sleeper_spacing) and sleeper_spacing > 0):
        raise ValueError(f"sleeper_spacing must be > 0 m, got {sleeper_spacing!r}")
    return max(1, round(window_m / sleeper_spacing)) * sleeper_spacing


def moving_mean_over_distance(y: np.ndarray, travelled_m: np.ndarray, window_m: float) -> np.ndarray:
    """Mean of ``y`` over the ``window_m`` of track centred on every sample.

    Parameters
    ----------
    y : ndarray, shape (channels, N) or (N,)
        Signal(s), any unit.
    travelled_m : ndarray, shape (N,)
        Distance travelled at every sample, m (non-decreasing).
    window_m : float
        Window length, m (> 0).

    Returns
    -------
    ndarray, shape of ``y``
        ``(1/W) ∫ y ds`` over ``[s − W/2, s + W/2]`` (``y`` held constant over
        each sample's step of travel), the window slid inside the record at its
        ends. A record shorter than ``W`` uses its whole length; one without
        travel (a standing train) its plain mean.
    """
    y = np.asarray(y, dtype=np.float64)
    s = np.asarray(travelled_m, dtype=np.float64)
    if s.ndim != 1 or y.shape[-1] != s.size:
        raise ValueError(f"travelled_m must be 1-D with one value per sample, got {s.shape} for {y.shape}")
    if not (math.isfinite(window_m) and window_m > 0):
        raise ValueError(f"window_m must be > 0 m, got {window_m!r}")
    if s.size == 0:
        return y.copy()
    if np.any(np.diff(s) < 0):
        raise ValueError("travelled_m must be non-decreasing")
    span = float(s[-1] - s[0])
    if span <= 0:
        return np.broadcast_to(y.mean(axis=-1, keepdims=True), y.shape).copy()
    w = min(float(window_m), span)
    ds = np.diff(s)
    # ∫ y ds with y held over [s_k, s_{k+1}) (the last sample's step taken as its predecessor's)
    steps = np.append(ds, ds[-1] if ds.size else 0.0)
    edges = np.concatenate([s[:1], s + steps])
    integral = np.concatenate([np.zeros(y.shape[:-1] + (1,)), np.cumsum(y * steps, axis=-1)], axis=-1)
    a = np.clip(s - 0.5 * w, edges[0], edges[-1] - w)
    b = a + w
    if y.ndim == 1:
        return (np.interp(b, edges, integral) - np.interp(a, edges, integral)) / w
    return np.vstack([(np.interp(b, edges, row) - np.interp(a, edges, row)) / w for row in integral])


def remove_static_load(
    y: np.ndarray, travelled_m: np.ndarray, window_m: float, sleeper_spacing: float
) -> np.ndarray:
    """``y`` less its moving mean over ``window_m`` rounded to whole sleeper bays.

    Parameters
    ----------
    y : ndarray, shape (channels, N) or (N,)
        Force channel(s), kN (any unit).
    travelled_m : ndarray, shape (N,)
        Distance travelled at every sample, m.
    window_m : float
        Window, m (> 0); :func:`bay_window_m` rounds it.
    sleeper_spacing : float
        d_s, m.

    Returns
    -------
    ndarray
        The dynamic part, in the unit of ``y``.
    """
    w = bay_window_m(window_m, sleeper_spacing)
    return np.asarray(y, dtype=np.float64) - moving_mean_over_distance(y, travelled_m, w)
