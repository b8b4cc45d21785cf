"""Stiffness steps of an amplitude profile where the signal is weak: the piecewise-constant estimate.

Why a small step reads wide (issue 33, docs/indicator.md *Small steps where the signal is weak*): the VKF's
track order at the set spatial resolution (3 m) passes the broadband noise inside its band, so every 25 cm bin
of ``sleeper_amp`` carries a fluctuation of its stated 1-σ (``sleeper_amp_sd``) correlated over about the
resolution. On the physics' track at 50 m/s (80 → 52 MN/m, 1.51 → 0.99 m/s²) under 1 m/s² of measurement
noise that 1-σ is 0.05–0.07 m/s², 11–13 % of the step: the step itself stays 1.8–3.3 m wide (10 → 90 %
around its 50 % point), but the profile leaves ±10 % of either level all along it, which the issue-26
measures read as a 24–39 m wide step ringing by 13–32 %. Nothing adapts to the amplitude or the SNR (the
band is set by the speed alone) and the roughness floor is not involved (``sleeper_amp_raw`` reads the
same); without the noise the same run reads 2.2 m and 5.6 %. No linear filter removes the fluctuation
without widening the step (its power is proportional to the band), and a total-variation estimate keeps
long noise excursions as stairs of their own (bins correlated over 12 bins look like 12× the evidence).

What does: the levels between change points, chosen by penalised least squares in units of the noise's
independent samples (the stated 1-σ times the square root of the bins per resolution),

    min over change points τ  Σ_segments Σ_i (y_i − ȳ_segment)² / (σ² c)  +  β · (number of change points)

with segments at least ``c`` bins (one resolution) long and change points on a grid of a quarter resolution
(:data:`GRID_PER_RESOLUTION`), solved exactly over that grid by optimal partitioning with pruning (PELT;
Killick, Fearnhead & Eckley 2012; a compiled kernel: on the profile of a 30-minute run, 246 000 bins, a few
tenths of a second per wheel, BENCHMARKS.md). A jump is kept where the data's evidence for it exceeds β in
chi-square units; between jumps the level is its bins' plain mean, so a stretch's mean is kept exactly.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["DEFAULT_STEP_PENALTY", "GRID_PER_RESOLUTION", "step_levels"]

#: Penalty β of one change point in chi-square units of independent samples (≈ 4² : a jump must stand out
#: by about four of its own standard deviations over the segments either side).
DEFAULT_STEP_PENALTY = 16.0
#: Change points lie on a grid of the resolution over this many (a resolution of 12 bins: every 3rd bin,
#: 0.75 m at 3 m): the position of a step to a quarter of the resolution it is seen with, at a seventh of
#: the CPU of every bin (the work grows with the candidates times the ends, both a third; BENCHMARKS.md).
GRID_PER_RESOLUTION = 4


def step_levels(values: np.ndarray, sd: np.ndarray, resolution_bins: float,
                penalty: float = DEFAULT_STEP_PENALTY) -> np.ndarray:
    """The piecewise-constant estimate of an amplitude profile (levels between change points).

    Parameters
    ----------
    values : numpy.ndarray
        The profile along the track, one value per bin in order (e.g. ``sleeper_amp``, m/s²; NaN: no value).
    sd : numpy.ndarray
        Its stated 1-σ per bin (same unit; NaN or ≤ 0: the bin has no value here).
    resolution_bins : float
        Bins over which the profile's noise is correlated (the track resolution over the bin length,
        3 m / 0.25 m = 12 by default), ≥ 1: the shortest segment, and the bins per independent sample.
    penalty : float
        Cost β of one change point in chi-square units (> 0; default :data:`DEFAULT_STEP_PENALTY`).

    Returns
    -------
    numpy.ndarray
        The estimate (same unit and length), NaN where a bin has no value. Each stretch of consecutive
        valid bins is segmented on its own, with the median 1-σ of that stretch; one shorter than two
        resolutions holds no change point: its mean.
    """
    y = np.asarray(values, dtype=np.float64)
    s = np.asarray(sd, dtype=np.float64)
    if y.ndim != 1 or s.shape != y.shape:
        raise ValueError(f"values, sd: must be 1-D of equal length, got {y.shape} and {s.shape}")
    c = float(resolution_bins)
    if not (math.isfinite(c) and c >= 1.0):
        raise ValueError(f"resolution_bins: must be a finite number >= 1, got {resolution_bins!r}")
    beta = float(penalty)
    if not (math.isfinite(beta) and beta > 0.0):
        raise ValueError(f"penalty: must be a finite number > 0, got {penalty!r}")
    out = np.full(y.shape, np.nan)
    ok = np.isfinite(y) & np.isfinite(s) & (s > 0)
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
    min_len = max(1, int(round(c)))
    grid = max(1, min_len // GRID_PER_RESOLUTION)
    for lo, hi in zip(edges[::2], edges[1::2], strict=True):
        seg = y[lo:hi]
        sigma = float(np.median(s[lo:hi])) * math.sqrt(c)
        out[lo:hi] = np.mean(seg) if seg.size < 2 * min_len else _pelt(seg, sigma, beta, min_len, grid)
    return out


def _pelt(y: np.ndarray, sigma: float, beta: float, min_len: int, grid: int) -> np.ndarray:
    """Optimal partitioning of one stretch with pruning (Gaussian cost of a constant level)."""
    n = y.size
    ref = float(np.mean(y))  # cumulative sums about the mean: no cancellation in s2 − s1²/L
    cs = np.r_[0.0, np.cumsum(y - ref)]
    cs2 = np.r_[0.0, np.cumsum((y - ref) ** 2)]
    last = _pelt_changes(cs, cs2, 1.0 / (sigma * sigma), float(beta), int(min_len), int(grid))
    out = np.empty(n)
    t = n
    while t > 0:
        s0 = int(last[t])
        out[s0:t] = ref + (cs[t] - cs[s0]) / (t - s0)
        t = s0
    return out


@numba.njit(cache=True, nogil=True)
def _pelt_changes(cs: np.ndarray, cs2: np.ndarray, inv: float, beta: float, min_len: int,
                  grid: int) -> np.ndarray:  # pragma: no cover - compiled
    """The start of the last segment before every segment end ``t`` of the optimal partition of ``y[:t]``.

    PELT over the segment ends on multiples of ``grid`` and the stretch's end.

    Parameters
    ----------
    cs, cs2 : numpy.ndarray
        (n + 1,) cumulative sums of the values and of their squares (about a reference), from 0.
    inv : float
        1 / σ² of the cost, 1/(m/s²)².
    beta : float
        Cost of one change point.
    min_len : int
        Shortest segment, bins.
    grid : int
        Change points lie on multiples of it, bins (≥ 1).

    Returns
    -------
    numpy.ndarray
        (n + 1,) int64: ``last[t]`` the start of the segment ending at ``t`` (0 where none ends there).
        The candidates' data are kept contiguous (position, cumulative sums, best cost), in the order:
        those too recent to end a segment, the kept ones, then ``t``; of equal totals the first is taken.
    """
    n = cs.size - 1
    best = np.full(n + 1, np.inf)
    best[0] = -beta
    last = np.zeros(n + 1, dtype=np.int64)
    cu = np.zeros(n + 2, dtype=np.int64)  # the candidates: position, its sums and best total
    c1 = np.zeros(n + 2)
    c2 = np.zeros(n + 2)
    cb = np.zeros(n + 2)
    nu = np.zeros(n + 2, dtype=np.int64)
    n1 = np.zeros(n + 2)
    n2 = np.zeros(n + 2)
    nb = np.zeros(n + 2)
    cost = np.empty(n + 2)
    cb[0] = -beta
    nc = 1
    t = min_len
    while t <= n:
        if t % grid != 0 and t != n:
            t = min(t + grid - t % grid, n)
            continue
        st1 = cs[t]
        st2 = cs2[t]
        bt = np.inf
        bj = -1
        for k in range(nc):
            length = t - cu[k]
            if length >= min_len:
                s1 = st1 - c1[k]
                c = (st2 - c2[k] - s1 * s1 / length) * inv
                cost[k] = c
                total = cb[k] + c + beta
                if bj < 0 or total < bt:
                    bt = total
                    bj = cu[k]
        if bj >= 0:
            best[t] = bt
            last[t] = bj
            m = 0
            for k in range(nc):
                if t - cu[k] < min_len:
                    nu[m] = cu[k]
                    n1[m] = c1[k]
                    n2[m] = c2[k]
                    nb[m] = cb[k]
                    m += 1
            for k in range(nc):
                if t - cu[k] >= min_len and cb[k] + cost[k] <= bt:
                    nu[m] = cu[k]
                    n1[m] = c1[k]
                    n2[m] = c2[k]
                    nb[m] = cb[k]
                    m += 1
            nu[m] = t
            n1[m] = st1
            n2[m] = st2
            nb[m] = bt
            m += 1
            cu, nu = nu, cu
            c1, n1 = n1, c1
            c2, n2 = n2, c2
            cb, nb = nb, cb
            nc = m
        t += 1
    return last
