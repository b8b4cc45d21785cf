"""Solve of a railway order recipe: stationary wheel orders, then the wide track orders.

Why two passes (issue 26)
-------------------------
The track orders (the sleeper passage ``f_s`` and its harmonics) are wide: a
3 m spatial resolution needs a band of ±0.35 wheel orders, which holds wheel
order 5 (0.18 orders from ``f_s`` on 0.92 m wheels; 9 and 10 lie in the band
of ``2 f_s``). A stiffness change makes the sleeper envelope change, and the
change has spectral content at that wheel order's frequency too. In one joint
least-squares solve the narrow wheel order takes all content at its own line
(its structural penalty is zero there; the track order's is not), whatever its
bandwidth: the wheel order's estimate is the projection of the signal on its
line over the filter's memory, the sleeper envelope loses that share, and the
loss shows as a ripple at the beat between the two orders (15.8 m on 0.6 m
sleepers and 0.92 m wheels) decaying over the wheel filter's memory (~30 m at
0.1 orders). Measured on the physics runs ``trans2_v30`` / ``trans2_v42``:
12–14 % of the step, and a weak 30 MN/m segment between two 120 MN/m ones read
+37 % high 10–20 m from its edges; with the wheel orders removed (or wheel order
5 alone) it disappears (BENCHMARKS.md, issue 26).

What tells a wheel order from the track's content at its line is physics, not
the bandwidth: out-of-roundness is fixed to the wheel, so its response changes
only with the wheel's speed (the excitation frequency ``l·v/(π d_w)`` moves
along the wheel–track frequency response), never with the place; the track's
content at the line comes and goes with the place. So:

1. **wheel pass** — every order of the recipe at the wheel orders' narrow
   bandwidth (the recipe before issue 15): the lines (sleeper passage,
   harmonics, wheel orders) separated by frequency; cheap (a narrow band
   decimates far);
2. the wheel orders that lie inside a track order's band
   (:func:`in_band_wheel_rows`) are replaced by a **function of speed**: a
   local-linear regression of their wheel-pass envelope over log-speed with a
   Gaussian kernel of :data:`SPEED_KERNEL_REL` (:func:`fit_over_speed`). At a
   steady speed that is one phasor over the whole stretch solved, so the
   track's share of it averages out over the stretch (it falls like 1/length,
   where the local estimate kept all of it); where the train accelerates the
   kernel spans the stretch in which the speed stays within ±1 %;
3. **track pass** — the track orders alone, at their own (wide) bandwidths, on
   the signal less the wheel orders' waveforms (full rate, one compiled pass).

The wheel orders outside the track bands keep their wheel-pass envelopes; they
lie ≥ 0.8 orders from any track order, where the track filter passes < 8 %.

Limit (said in docs/indicator.md): within one record the track's content at the
line over the whole stretch cannot be told from a wheel polygon. On the 160 m
physics runs that content is the acceleration of a 0.8 µm (trans2_v30) or
2.6 µm (trans2_v42) order-5 polygon, large because their 40 m segments are
2.5 beat lengths and the edges add; in runs of kilometres it is negligible.

A recipe with no wheel order inside a track band (e.g. ``track_resolution_m``
None, or few wheel orders) is solved in one joint VKF as before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .order_residual import railway_residual
from .orders import OrderTrack
from .vkf import VKFResult, vkf

if TYPE_CHECKING:
    from .recipe import OrderRecipe

__all__ = ["SPEED_KERNEL_REL", "RecipeSolution", "SpeedFit", "fit_over_speed", "in_band_wheel_rows",
           "solve_recipe"]

#: width (1 σ) of the Gaussian kernel over speed of the stationary wheel-order fit, relative
SPEED_KERNEL_REL = 0.01
#: bins per kernel σ of the speed fit
_BINS_PER_SIGMA = 4
#: kernel truncation, σ
_KERNEL_SIGMAS = 4.0
#: wheel-pass envelopes are sampled for the fit and the waveforms every this much travel, m
_GRID_M = 0.05


def in_band_wheel_rows(labels: tuple[str, ...], multipliers: np.ndarray,
                       bandwidth_per_speed: np.ndarray) -> np.ndarray:
    """Rows of the wheel orders that lie inside a track order's band.

    A wheel order ``l`` is inside the band of a track order ``h`` when their
    frequencies are closer than the track order's full -3 dB bandwidth
    (both scale with speed, so this holds at every speed or at none): there
    the track filter still passes ≥ 13 % (q = 2), and the wheel order's line
    takes a share of every change of the track order.

    Parameters
    ----------
    labels : tuple of str
        Order labels (track orders first, wheel orders as digits).
    multipliers, bandwidth_per_speed : ndarray, shape (s,)
        Hz per m/s.

    Returns
    -------
    ndarray of int
    """
    track = [i for i, x in enumerate(labels) if not x.isdigit()]
    wheel = [i for i, x in enumerate(labels) if x.isdigit()]
    rows = [j for j in wheel
            if any(abs(float(multipliers[j]) - float(multipliers[i])) < float(bandwidth_per_speed[i])
                   and bandwidth_per_speed[i] > bandwidth_per_speed[j] for i in track)]
    return np.array(rows, dtype=np.int64)


@dataclass(frozen=True)
class SpeedFit:
    """A complex envelope as a function of speed (local-linear over log-speed).

    Attributes
    ----------
    log_v0 : float
        ln of the speed (m/s) of bin 0.
    step : float
        Bin width in ln-speed.
    a, b : ndarray, complex, shape (channels, n_bins)
        Value at the bin centre and slope per unit ln-speed.
    """

    log_v0: float
    step: float
    a: np.ndarray
    b: np.ndarray

    def __call__(self, speed: np.ndarray) -> np.ndarray:
        """Values at speeds (m/s, > 0), shape (channels, len(speed)); speeds beyond the
        fitted range take the nearest bin's line."""
        ln = np.log(np.asarray(speed, dtype=np.float64))
        pos = (ln - self.log_v0) / self.step
        j = np.clip(np.rint(pos), 0, self.a.shape[1] - 1).astype(np.int64)
        d = ln - (self.log_v0 + j * self.step)
        return self.a[:, j] + self.b[:, j] * d[None, :]


def fit_over_speed(values: np.ndarray, speed: np.ndarray, mask: np.ndarray,
                   rel_width: float = SPEED_KERNEL_REL) -> SpeedFit | None:
    """Local-linear kernel regression of complex envelopes over log-speed.

    At every speed ``v`` the value and slope minimise
    ``Σ_k K(ln v_k − ln v) |values_k − a − b (ln v_k − ln v)|²`` with a
    Gaussian ``K`` of width ``rel_width`` (on a grid of bins a quarter of that
    wide, the sums gathered per bin and convolved). Where every sample has
    (nearly) one speed the slope is undetermined and held at 0 by a small
    ridge: the fit is then the mean.

    Parameters
    ----------
    values : ndarray, complex, shape (channels, M)
        Envelopes at the samples.
    speed : ndarray, shape (M,)
        Speed at the samples, m/s.
    mask : ndarray of bool, shape (M,)
        Samples that count (moving, finite).
    rel_width : float
        Kernel σ, relative speed (> 0).

    Returns
    -------
    SpeedFit or None
        None when no sample counts.
    """
    if not rel_width > 0:
        raise ValueError(f"rel_width must be > 0, got {rel_width!r}")
    vals = np.asarray(values, dtype=np.complex128)
    ok = np.asarray(mask, dtype=bool) & (np.asarray(speed) > 0) & np.all(np.isfinite(vals), axis=0)
    if not np.any(ok):
        return None
    ln = np.log(np.asarray(speed, dtype=np.float64)[ok])
    vals = vals[:, ok]
    step = rel_width / _BINS_PER_SIGMA
    lo = float(ln.min())
    j = np.rint((ln - lo) / step).astype(np.int64)
    nb = int(j.max()) + 1
    d = ln - (lo + j * step)
    s0 = np.bincount(j, minlength=nb).astype(np.float64)
    s1 = np.bincount(j, d, minlength=nb)
    s2 = np.bincount(j, d * d, minlength=nb)
    t0 = np.stack([np.bincount(j, v.real, minlength=nb) + 1j * np.bincount(j, v.imag, minlength=nb) for v in vals])
    t1 = np.stack([np.bincount(j, d * v.real, minlength=nb) + 1j * np.bincount(j, d * v.imag, minlength=nb)
                   for v in vals])
    half = int(math.ceil(_KERNEL_SIGMAS * _BINS_PER_SIGMA))
    off = np.arange(-half, half + 1)
    k0 = np.exp(-0.5 * (off / _BINS_PER_SIGMA) ** 2)
    dk = off * step  # source bin centre minus target bin centre, ln-speed

    def conv(x: np.ndarray, kern: np.ndarray) -> np.ndarray:
        # target c gathers source c + off[i] with kern[i]: a correlation (convolution with the reversal)
        rows = np.atleast_2d(x)
        return np.stack([np.convolve(r, kern[::-1])[half : half + nb] for r in rows])

    # moments about each target bin centre: d' = d + dk
    m0 = conv(s0, k0)[0]
    m1 = conv(s1, k0)[0] + conv(s0, k0 * dk)[0]
    m2 = conv(s2, k0)[0] + 2.0 * conv(s1, k0 * dk)[0] + conv(s0, k0 * dk * dk)[0]
    n0 = conv(t0.real, k0) + 1j * conv(t0.imag, k0)
    n1 = (conv(t1.real, k0) + 1j * conv(t1.imag, k0)) + (conv(t0.real, k0 * dk) + 1j * conv(t0.imag, k0 * dk))
    m2 = m2 + 1e-6 * rel_width**2 * m0  # ridge: the slope of a (nearly) single-speed stretch is 0
    det = m0 * m2 - m1 * m1
    good = (m0 > 1e-12) & (det > 0)
    safe = np.where(good, det, 1.0)
    a = np.where(good, (m2 * n0 - m1 * n1) / safe, 0.0)
    b = np.where(good, (m0 * n1 - m1 * n0) / safe, 0.0)
    return SpeedFit(log_v0=lo, step=step, a=a, b=b)


@dataclass
class RecipeSolution:
    """Envelopes of a recipe's orders over a record (the result of :func:`solve_recipe`).

    Attributes
    ----------
    info : dict
        ``chunks``: the VKF solves' chunk information (wheel pass first);
        ``stationary_rows``: rows replaced by their fit over speed.
    """

    wheel_pass: VKFResult
    track_pass: VKFResult | None
    track_rows: np.ndarray
    stationary: dict[int, SpeedFit] = field(default_factory=dict)
    speed: np.ndarray | None = None
    min_speed: float = 0.0
    y_is_1d: bool = True
    info: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.wheel_pass)

    def envelope_at(self, index: Any) -> np.ndarray:
        """Envelopes (peak phasors) at sample indices, shape ``([channels,] s, len(index))``.

        Same contract as :meth:`app.analysis.vkf.VKFResult.envelope_at`: NaN
        where an order is not trackable.
        """
        index = np.asarray(index, dtype=np.int64).reshape(-1)
        env = np.array(self.wheel_pass.envelope_at(index), dtype=np.complex128)
        if self.y_is_1d:
            env = env[None]
        if self.track_pass is not None:
            tr = self.track_pass.envelope_at(index)
            env[:, self.track_rows] = tr[None] if self.y_is_1d else tr
        if self.stationary:
            v = np.asarray(self.speed, dtype=np.float64)[index]
            moving = v >= self.min_speed
            for row, fit in self.stationary.items():
                local = env[:, row]
                fitted = fit(np.maximum(v, 1e-9))
                env[:, row] = np.where(moving[None, :] & np.isfinite(local), fitted, local)
        return env[0] if self.y_is_1d else env


def solve_recipe(recipe: OrderRecipe, y: Any, fs: float, speed: np.ndarray, phase0: np.ndarray,
                 psi: np.ndarray) -> RecipeSolution:
    """Extract a recipe's orders: wheel pass, stationary in-band wheel orders, track pass.

    Parameters
    ----------
    recipe : OrderRecipe
    y : array_like, shape (N,) or (channels, N)
        Signal(s) of one wheel, m/s² (kN).
    fs : float
        Sample rate, Hz.
    speed : ndarray, shape (N,)
        Absolute speed, m/s.
    phase0 : ndarray, shape (s,)
        Phase of every order before the first sample, rad.
    psi : ndarray, shape (N,)
        Phase per unit multiplier (``phase0 / multipliers`` plus the travel), rad.

    Returns
    -------
    RecipeSolution
    """
    mult, bwps, q = recipe.multipliers, recipe.bandwidth_per_speed, recipe.filter_order
    v = np.abs(np.asarray(speed, dtype=np.float64))
    vb = np.maximum(v, recipe.floor_speed)
    inband = in_band_wheel_rows(recipe.labels, mult, bwps)
    y_is_1d = np.ndim(y) == 1
    if inband.size == 0:
        res = vkf(y, fs, OrderTrack(v, mult), OrderTrack(vb, bwps), q, chunk_duration=np.inf, phase0=phase0)
        return RecipeSolution(res, None, recipe.track_rows, y_is_1d=y_is_1d,
                              info={"chunks": res.info["chunks"], "stationary_rows": []})
    track, wheel = recipe.track_rows, recipe.wheel_rows
    narrow = bwps.copy()
    narrow[track] = float(bwps[wheel].min())
    first = vkf(y, fs, OrderTrack(v, mult), OrderTrack(vb, narrow), q, chunk_duration=np.inf, phase0=phase0)
    y2 = np.atleast_2d(np.asarray(y, dtype=np.float64))
    n = y2.shape[1]
    step = max(1, int(fs * _GRID_M / max(float(v.max()), 1.0)))
    grid = np.arange(0, n, step)
    env = np.array(first.envelope_at(grid), dtype=np.complex128)
    if y_is_1d:
        env = env[None]
    vg = v[grid]
    moving = vg >= recipe.min_speed
    fits: dict[int, SpeedFit] = {}
    for row in inband:
        fit = fit_over_speed(env[:, row], vg, moving)
        if fit is None:
            continue
        fits[int(row)] = fit
        fitted = fit(np.maximum(vg, 1e-9))
        env[:, row] = np.where(moving[None, :] & np.isfinite(env[:, row]), fitted, env[:, row])
    env[:, track] = 0.0
    env = np.nan_to_num(env, nan=0.0)
    rest = np.stack([railway_residual(y2[c], psi, env[c], step, mult, recipe.powers, track.size)
                     for c in range(y2.shape[0])])
    second = vkf(rest[0] if y_is_1d else rest, fs, OrderTrack(v, mult[track]), OrderTrack(vb, bwps[track]), q,
                 chunk_duration=np.inf, phase0=phase0[track])
    return RecipeSolution(first, second, track, fits, v, recipe.min_speed, y_is_1d,
                          info={"chunks": first.info["chunks"] + second.info["chunks"],
                                "stationary_rows": [int(r) for r in fits]})
