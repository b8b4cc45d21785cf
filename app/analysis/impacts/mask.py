"""Keeping track impacts out of the sleeper indicator: the bins they disturb are bridged.

A dipped weld puts a transient into the axle-box acceleration whose energy
near the sleeper-passage frequency the track order takes for sleeper
passage: on smooth track a 0.3 mm, 1 m weld makes the profile dip by tens of
per cent over a few metres (the order's impulse response, the spatial
resolution ``track_resolution_m``). Within :func:`mask_half_width` of a
detected track impact the indicator is therefore not measured but bridged:
replaced, per wheel, by the straight line between the nearest undisturbed
bins on either side (:func:`bridge`). A wheel flat needs no mask: it is
periodic in the wheel's revolution, so the wheel orders take it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["mask_half_width", "impact_mask", "bridge"]


def mask_half_width(length_m: float, track_resolution_m: float | None) -> float:
    """Half width of the bridged stretch around an impact, m.

    Half the dip, plus 1.5 × the track orders' resolution (the 10–90 % width
    of their step response: their impulse response has faded to a few per
    cent there), plus 0.5 m for the position.
    """
    res = 3.0 if track_resolution_m is None else float(track_resolution_m)
    if not (math.isfinite(length_m) and length_m >= 0 and math.isfinite(res) and res > 0):
        raise ValueError("length_m, track_resolution_m: must be finite, >= 0 and > 0")
    return 0.5 * float(length_m) + 1.5 * res + 0.5


def impact_mask(bin_centres_m: np.ndarray, impacts_m: Sequence[float], half_widths_m: Sequence[float]) -> np.ndarray:
    """Which bins lie within the half width of an impact.

    Parameters
    ----------
    bin_centres_m : numpy.ndarray
        Bin centres, m on the km axis.
    impacts_m, half_widths_m : sequence of float
        Impact positions and their half widths, m.

    Returns
    -------
    numpy.ndarray
        bool, like ``bin_centres_m``.
    """
    x = np.asarray(bin_centres_m, dtype=np.float64)
    pos = np.asarray(impacts_m, dtype=np.float64)
    half = np.asarray(half_widths_m, dtype=np.float64)
    if pos.shape != half.shape or pos.ndim != 1:
        raise ValueError("impacts_m, half_widths_m: must be 1-D of equal length")
    out = np.zeros(x.shape, dtype=bool)
    if pos.size == 0 or x.size == 0:
        return out
    order = np.argsort(pos)
    pos, half = pos[order], half[order]
    lo = np.searchsorted(x, pos - half, side="left") if np.all(np.diff(x) >= 0) else None
    if lo is None:  # unsorted bins
        for p, h in zip(pos, half, strict=True):
            out |= np.abs(x - p) <= h
        return out
    hi = np.searchsorted(x, pos + half, side="right")
    for a, b in zip(lo, hi, strict=True):
        out[a:b] = True
    return out


def bridge(x: np.ndarray, values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``values`` with the masked entries replaced by the straight line between their unmasked neighbours.

    Parameters
    ----------
    x : numpy.ndarray
        Positions, m (ascending).
    values : numpy.ndarray
        One value per position (NaN allowed: NaNs are neither bridged from nor filled).
    mask : numpy.ndarray
        bool: entries to replace.

    Returns
    -------
    numpy.ndarray
        A copy. A masked entry with finite unmasked values on one side only takes the nearest of
        them; with none anywhere, NaN.
    """
    x = np.asarray(x, dtype=np.float64)
    v = np.array(values, dtype=np.float64, copy=True)
    m = np.asarray(mask, dtype=bool)
    if not (x.shape == v.shape == m.shape and x.ndim == 1):
        raise ValueError("x, values, mask: must be 1-D of equal length")
    good = ~m & np.isfinite(v)
    if not m.any():
        return v
    if not good.any():
        v[m] = np.nan
        return v
    v[m] = np.interp(x[m], x[good], v[good])
    return v
