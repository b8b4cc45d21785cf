"""How repeatable the measurement is: one bin's ``ln A`` between two passes at similar speed
(:func:`bin_repeatability`, the bin's own share of the index's uncertainty), and the systematic
level of each wheel against the others on its rail and the right/left rail difference
(:func:`wheel_offsets`: a sensor's gain, or the rail)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from app.analysis.robust import mad_sd
from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE, log_speeds_matched
from app.analysis.stiffness.reference_curve.curves import GROUP_BLOCKS, BlockSamples, ReferenceCurve
from app.analysis.stiffness.reference_curve.smoother import group_median

__all__ = ["WheelOffset", "bin_repeatability", "wheel_offsets"]


@dataclass(frozen=True)
class WheelOffset:
    """Systematic level of one wheel (ln units) against the other wheels of its rail.

    ``offset`` is the median of the wheel's residuals ``ln A - m(location) - g(v)``
    at locations passed by other wheels too (a sensor gain error shows here: a
    20 % too high gain gives about ``+ln(1.2) / 2`` with two wheels per rail);
    NaN when no other wheel passed its locations.
    """

    wheel: str
    offset: float
    low: float
    high: float
    n_samples: int


def _codes(values: np.ndarray) -> np.ndarray:
    """Integer codes of labels (numbers as they are; anything else by its text)."""
    if values.dtype.kind in "iub":
        return values.astype(np.int64)
    return np.unique(values.astype(str), return_inverse=True)[1].ravel()


def bin_repeatability(
    log_amp: np.ndarray, log_speed: np.ndarray, rail: np.ndarray, bin_index: np.ndarray, pass_id: np.ndarray,
    *, speed_tolerance: float = DEFAULT_SPEED_TOLERANCE,
) -> float:
    """Standard deviation of one bin's ``ln A`` between two passes at similar speed (ln units).

    Pairs are passes (``pass_id``: e.g. run and wheel) of the same rail and bin
    whose speeds differ by at most ``tol``; the robust standard deviation
    (:func:`app.analysis.robust.mad_sd`) of their differences over √2. NaN with fewer than 100 pairs.
    """
    y = np.asarray(log_amp, dtype=np.float64)
    u = np.asarray(log_speed, dtype=np.float64)
    if not (u.shape == y.shape == np.shape(rail) == np.shape(bin_index) == np.shape(pass_id)):
        raise ValueError("log_amp, log_speed, rail, bin_index, pass_id: must have equal shapes")
    ok = np.isfinite(y) & np.isfinite(u)
    y, u = y[ok], u[ok]
    r = _codes(np.asarray(rail)[ok])
    b = np.asarray(bin_index)[ok].astype(np.int64)
    p = _codes(np.asarray(pass_id)[ok])
    order = np.lexsort((p, b, r))
    r, b, p, y, u = r[order], b[order], p[order], y[order], u[order]
    same = (r[1:] == r[:-1]) & (b[1:] == b[:-1]) & (p[1:] != p[:-1])
    same &= log_speeds_matched(u[1:] - u[:-1], speed_tolerance)
    d = (y[1:] - y[:-1])[same]
    if d.size < 100:
        return float("nan")
    return mad_sd(d) / math.sqrt(2.0)


def wheel_offsets(samples: BlockSamples, curves: Mapping[str, ReferenceCurve], *, n_boot: int = 200,
                  confidence: float = 0.9, seed: int = 0) -> tuple[tuple[WheelOffset, ...], float]:
    """Per-wheel systematic offsets against the other wheels of the rail, and the rail difference.

    Residuals ``e = ln A - g_class(v) - m(location)`` with ``m`` the median over
    all passes of the location; a wheel's offset is the median of its
    residuals at locations passed by another wheel (interval: bootstrap over
    200 m groups). The rail difference is the median over blocks of the
    location effect of rail 2 minus rail 1 (the two rails sorted by label).
    """
    if len(samples) == 0:
        return (), float("nan")
    g = np.full(len(samples), np.nan)
    for c, curve in curves.items():
        m = samples.cls == c
        if m.any() and curve.log_speed.size:
            g[m] = curve.evaluate(np.exp(samples.log_speed[m]))[0]
    y = samples.log_amp - g
    _, loc = np.unique(samples.location, return_inverse=True)
    loc = loc.ravel()
    n_loc = int(loc.max()) + 1
    effect = group_median(y, loc, n_loc)
    resid = y - effect[loc]
    # locations passed by more than one wheel
    wheel_id = np.unique(samples.wheel.astype(str), return_inverse=True)[1].ravel()
    wmin = np.full(n_loc, np.iinfo(np.int64).max)
    wmax = np.full(n_loc, -1)
    np.minimum.at(wmin, loc, wheel_id)
    np.maximum.at(wmax, loc, wheel_id)
    shared = (wmin != wmax)[loc] & np.isfinite(resid)
    rng = np.random.default_rng(seed)
    group = samples.block // GROUP_BLOCKS
    out = []
    for w in sorted(set(samples.wheel.astype(str))):
        m = shared & (samples.wheel.astype(str) == w)
        if m.sum() < 10:
            out.append(WheelOffset(w, float("nan"), float("nan"), float("nan"), int(m.sum())))
            continue
        e, gr = resid[m], group[m]
        gu, gi = np.unique(gr, return_inverse=True)
        members = [e[gi.ravel() == k] for k in range(gu.size)]
        boots = [np.median(np.concatenate([members[k] for k in rng.integers(0, gu.size, gu.size)]))
                 for _ in range(n_boot)]
        a = (1 - confidence) / 2
        lo, hi = np.quantile(boots, [a, 1 - a])
        out.append(WheelOffset(w, float(np.median(e)), float(lo), float(hi), int(m.sum())))
    rails = sorted(set(samples.rail.astype(str)))
    diff = float("nan")
    if len(rails) == 2:
        per = {}
        for rl in rails:
            m = (samples.rail.astype(str) == rl) & np.isfinite(y)
            blocks = samples.block[m]
            bu, bi = np.unique(blocks, return_inverse=True)
            per[rl] = dict(zip(bu.tolist(), group_median(y[m], bi.ravel(), bu.size).tolist(), strict=True))
        common = sorted(set(per[rails[0]]) & set(per[rails[1]]))
        if common:
            diff = float(np.median([per[rails[1]][b] - per[rails[0]][b] for b in common]))
    return tuple(out), diff
