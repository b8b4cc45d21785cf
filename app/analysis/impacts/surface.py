"""The running surface under a wheel, estimated back from its axle-box acceleration.

A height ``r`` of the rail or wheel surface under the contact (up positive,
a dip is negative) drives the wheel through the linear wheel–track system of
:mod:`app.analysis.stiffness.track_dynamics`, ``a = H(f) r`` with
``H = (1 / m) / (alpha_w + alpha_c + alpha_t)``. Its inverse is physical:

    r = m (alpha_w + alpha_c + alpha_t) a

the wheel's own displacement (``alpha_w a m = -a / omega²``) less the
deflections of the contact and the rail under the dynamic force ``m a``.

Along the track the frequency of a surface wavelength ``lambda`` is
``v / lambda``. :func:`surface_estimate` therefore works in the wheel's
travelled distance: the acceleration is averaged onto a grid of ``step_m``
(a box anti-alias filter), cut into windows of :data:`WINDOW_CELLS` cells
(50 % overlap, Hann, summing to one) within which the speed is taken as
constant, inverted with ``1 / H(v kappa)`` and band-limited to the
wavelengths ``band_m`` (and to frequencies under :data:`F_MAX_HZ`, above which
the rail model — 12 elements per sleeper bay — is not credible).

The periodic parts of the signal are lines in this domain, whatever the
speed: the sleeper passage and its harmonics at ``h / d_s`` and the wheel's
out-of-roundness orders at ``l / (pi d_w)`` cycles per metre of travel. They
are notched out (``lines_per_m``, ± ``line_halfwidth_per_m``), which takes a
small slice of an isolated dip's broad spectrum and leaves the rest: unlike
the VKF's track order, whose band of a few metres' resolution takes much of
a weld's energy (a weld's response peaks at the wheel–track resonance, near
the sleeper-passage frequency), so the VKF residual would not do here.

The track is the product's generic one (:class:`TrackParameters` defaults:
UIC60 on 80 MN/m ballast, a 592 kg unsprung mass): the support stiffness
matters at the coupled resonance only, so depths of long dips carry its
uncertainty (stated with the measured errors in docs/indicator.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from app.analysis.stiffness.track_dynamics import TrackParameters, wheel_rail_transfer

__all__ = ["F_MAX_HZ", "WINDOW_CELLS", "SurfaceEstimate", "surface_estimate", "band_gain"]

#: Highest frequency inverted, Hz (faded out from 0.8 of it).
F_MAX_HZ = 2500.0
#: Cells per inversion window (a power of two: 20 m at the default step).
WINDOW_CELLS = 2048
#: Relative width of the raised-cosine edges of the wavelength band.
_EDGE = 0.25


@dataclass(frozen=True)
class SurfaceEstimate:
    """The surface height under one wheel on a grid of its travelled distance.

    Attributes
    ----------
    s0 : float
        Travelled distance of cell 0's start, m.
    step : float
        Cell length, m.
    height : numpy.ndarray
        Band-limited surface height per cell, m (0 where not valid).
    valid : numpy.ndarray
        bool per cell: samples there, moving faster than the minimum speed.
    speed : numpy.ndarray
        Mean speed per cell, m/s (NaN where no sample).
    band_m : tuple of float
        Wavelength band of ``height``, m (the short end raised where the speed needs it).
    notches : tuple of (float, float)
        Lines notched out: (wavenumber, half width), 1/m.
    """

    s0: float
    step: float
    height: np.ndarray
    valid: np.ndarray
    speed: np.ndarray
    band_m: tuple[float, float]
    notches: tuple[tuple[float, float], ...] = ()

    def gain(self, kappa: np.ndarray) -> np.ndarray:
        """What the estimate kept of each wavenumber (1/m): the cell average, the band, less the notches."""
        k = np.asarray(kappa, dtype=np.float64)
        g = band_gain(k, self.band_m) * np.sinc(k * self.step)
        for k0, half in self.notches:
            g[np.abs(np.abs(k) - k0) <= half] = 0.0
        return g

    @property
    def s(self) -> np.ndarray:
        """Cell centres, m of travelled distance."""
        return self.s0 + (np.arange(self.height.size) + 0.5) * self.step


def _grid() -> np.ndarray:
    return np.concatenate([np.arange(1.0, 1400.0, 1.0), np.arange(1400.0, F_MAX_HZ + 4.0, 4.0)])


@lru_cache(maxsize=8)
def _inverse(params: TrackParameters) -> np.ndarray:
    """``1 / H`` on :func:`_grid` (m per m/s²)."""
    return 1.0 / wheel_rail_transfer(params, _grid())


def band_gain(kappa: np.ndarray, band_m: tuple[float, float]) -> np.ndarray:
    """Raised-cosine band-pass in wavelength (half gain at the band edges) at wavenumbers ``kappa`` (1/m)."""
    k = np.abs(np.asarray(kappa, dtype=np.float64))
    lo, hi = band_m
    w = math.log1p(_EDGE)
    with np.errstate(divide="ignore"):
        lam = np.where(k > 0, 1.0 / np.maximum(k, 1e-300), np.inf)
        u1 = np.log(lam / lo) / w
        u2 = np.log(hi / lam) / w

    def edge(u: np.ndarray) -> np.ndarray:
        return np.where(u >= 0.5, 1.0, np.where(u <= -0.5, 0.0, 0.5 * (1.0 + np.sin(np.pi * np.clip(u, -0.5, 0.5)))))

    return edge(u1) * edge(u2)


def surface_estimate(
    accel: np.ndarray,
    travelled_m: np.ndarray,
    speed_mps: np.ndarray,
    *,
    params: TrackParameters | None = None,
    step_m: float = 0.01,
    band_m: tuple[float, float] = (0.025, 2.5),
    min_speed_mps: float = 5.0,
    lines_per_m: tuple[float, ...] = (),
    line_halfwidth_per_m: float = 0.1,
    subtract: Callable[[np.ndarray], np.ndarray] | None = None,
    fs: float | None = None,
) -> SurfaceEstimate:
    """Estimate the surface height under a wheel from its axle-box acceleration.

    Parameters
    ----------
    accel : numpy.ndarray
        Axle-box acceleration, m/s².
    travelled_m : numpy.ndarray
        Distance the wheel has travelled at each sample, m (non-decreasing).
    speed_mps : numpy.ndarray
        Absolute speed at each sample, m/s.
    params : TrackParameters, optional
        The wheel–track system (default :class:`TrackParameters`).
    step_m : float
        Grid step, m (default 1 cm).
    band_m : (float, float)
        Wavelength band kept, m (default 2.5 cm … 2.5 m); the short end is
        raised to ``v_max / F_MAX_HZ`` where the speed needs it.
    min_speed_mps : float
        Cells slower than this are not valid (default 5 m/s).
    lines_per_m : tuple of float
        Wavenumbers of periodic components to notch out, cycles per metre of travel.
    line_halfwidth_per_m : float
        Half width of each notch, 1/m (default 0.1: two bins of a 20 m window).
    subtract : callable, optional
        Known components to take out first: called with travelled distances
        (m, the centres of the cells), returns the acceleration there (m/s²),
        e.g. the wheel's out-of-roundness orders as the VKF extracted them.
        Evaluated per cell, not per sample: right for components much longer
        than a cell.
    fs : float, optional
        Sampling rate of ``accel``, Hz: frequencies above 0.4 ``fs`` (where a recording coarser than
        :data:`F_MAX_HZ` needs it) are left out, as above :data:`F_MAX_HZ`. None: :data:`F_MAX_HZ`.

    Notes
    -----
    The window is :data:`WINDOW_CELLS` cells (20 m at the default step); the
    band's short end is at least 2.5 cells.

    Returns
    -------
    SurfaceEstimate
    """
    a = np.asarray(accel, dtype=np.float64)
    s = np.asarray(travelled_m, dtype=np.float64)
    v = np.abs(np.asarray(speed_mps, dtype=np.float64))
    if not (a.ndim == 1 and a.shape == s.shape == v.shape):
        raise ValueError("accel, travelled_m, speed_mps: must be 1-D of equal length")
    if a.size < 2:
        raise ValueError("accel: needs at least 2 samples")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(v))):
        raise ValueError("travelled_m, speed_mps: must be finite")
    if np.any(np.diff(s) < -1e-9):
        raise ValueError("travelled_m: must not decrease")
    if fs is not None and not (math.isfinite(fs) and fs > 0):
        raise ValueError(f"fs: must be a finite rate > 0 Hz, got {fs!r}")
    f_max = F_MAX_HZ if fs is None else min(F_MAX_HZ, 0.4 * fs)
    if not (math.isfinite(step_m) and 0 < step_m <= 0.05):
        raise ValueError(f"step_m: must be in (0, 0.05] m, got {step_m!r}")
    lo, hi = (float(x) for x in band_m)
    if not (2 * step_m < lo < hi):
        raise ValueError(f"band_m: must satisfy 2 step_m < min < max, got {band_m!r}")
    params = TrackParameters() if params is None else params
    fin = np.isfinite(a)
    s0 = math.floor(float(s[0]) / step_m) * step_m
    idx = ((s - s0) * (1.0 / step_m)).astype(np.int64)  # s >= s0: truncation is the floor
    n = int(idx[-1]) + 1
    every = np.bincount(idx, minlength=n).astype(np.float64)
    all_finite = bool(fin.all())
    count = every if all_finite else np.bincount(idx[fin], minlength=n).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        y = (np.bincount(idx, weights=a, minlength=n) if all_finite
             else np.bincount(idx[fin], weights=a[fin], minlength=n)) / count
        vc = np.bincount(idx, weights=v, minlength=n) / every
    sampled = np.flatnonzero(np.isfinite(vc))
    if sampled.size and sampled.size < n:
        # a cell without a sample (a coarse recording: fewer samples than cells) moves at the speed of
        # the cells around it, so that it is interpolated below and not a gap in the valid cells
        vc = np.interp(np.arange(n), sampled, vc[sampled])
    moving = np.isfinite(vc) & (vc >= min_speed_mps)
    have = (count > 0) & moving
    v_max = float(np.nanmax(np.where(moving, vc, np.nan))) if moving.any() else min_speed_mps
    lo = max(lo, v_max / f_max, 2.5 * step_m)
    valid = np.zeros(n, dtype=bool)
    height = np.zeros(n)
    notches = tuple((float(k0), float(line_halfwidth_per_m)) for k0 in lines_per_m)
    if have.sum() < 2 or lo >= hi:
        return SurfaceEstimate(s0, step_m, height, valid, vc, (lo, hi), notches)
    # cells without a sample (coarse sampling) between ones with: interpolated; long gaps stay out
    cells = np.arange(n)
    good = np.flatnonzero(have)
    j = np.searchsorted(good, cells)
    near = np.minimum(np.abs(cells - good[np.clip(j - 1, 0, good.size - 1)]),
                      np.abs(good[np.clip(j, 0, good.size - 1)] - cells))
    valid = moving & (near <= max(4, int(0.05 / step_m)))
    if subtract is not None:
        y[good] -= np.asarray(subtract(s0 + (good + 0.5) * step_m), dtype=np.float64)
    y = np.where(valid, np.interp(cells, good, y[good]), 0.0)
    inv = _inverse(params)
    fgrid = _grid()
    w_n = WINDOW_CELLS
    hop = w_n // 2
    win = np.hanning(w_n + 1)[:w_n]  # periodic Hann: sums to one at 50 % overlap
    # each window is filtered inside a buffer twice its length (linear, not circular, convolution)
    n_fft = 2 * w_n
    kappa = np.fft.rfftfreq(n_fft, step_m)
    gain = band_gain(kappa, (lo, hi))  # the cell average is left in (SurfaceEstimate.gain says so)
    for k0, half in notches:
        gain[np.abs(kappa - k0) <= half] = 0.0
    pad = w_n
    yp = np.concatenate([np.zeros(pad), y, np.zeros(pad + w_n)])
    vp = np.concatenate([np.full(pad, np.nan), np.where(valid, vc, np.nan), np.full(pad + w_n, np.nan)])
    out = np.zeros(yp.size + n_fft)
    filters: dict[float, np.ndarray] = {}
    for start in range(pad - hop, n + pad, hop):
        seg_v = vp[start : start + w_n]
        if not np.any(np.isfinite(seg_v)):
            continue
        vbar = round(float(np.nanmean(seg_v)), 1)  # windows at one speed (to 0.1 m/s) share the filter
        g = filters.get(vbar)
        if g is None:
            f = vbar * kappa
            g = np.zeros(kappa.size, dtype=np.complex128)
            ok = (f >= fgrid[0]) & (f <= f_max)
            g[ok] = np.interp(f[ok], fgrid, inv.real) + 1j * np.interp(f[ok], fgrid, inv.imag)
            g *= gain * np.where(f <= 0.8 * f_max, 1.0,
                                 0.5 * (1.0 + np.cos(np.pi * np.clip((f / f_max - 0.8) / 0.2, 0.0, 1.0))))
            filters[vbar] = g
        buf = np.zeros(n_fft)
        buf[hop : hop + w_n] = yp[start : start + w_n] * win
        res = np.fft.irfft(np.fft.rfft(buf) * g, n_fft)
        a0 = start - hop
        if a0 >= 0:
            out[a0 : a0 + n_fft] += res
        else:
            out[: a0 + n_fft] += res[-a0:]
    height = np.where(valid, out[pad : pad + n], 0.0)
    return SurfaceEstimate(s0, step_m, height, valid, vc, (lo, hi), notches)
