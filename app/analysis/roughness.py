"""Rail roughness out of the sleeper-passage amplitude, as far as one pass allows, and its 1-σ.

What the VKF's sleeper order holds
----------------------------------
The sleeper order's envelope ``E`` (peak phasor at ``f_s = v/d_s``, m/s²) is the
sleeper-passage response ``S`` — parametric, set by the support under the
rail, the quantity the map should show — plus whatever broadband response falls
in the order's band: rail roughness, measurement noise, ``R``. ``R`` is not
synchronised to the sleepers, so its phase relative to ``S`` is random and
``E|E|² = |S|² + F`` with the **floor** ``F = E|R|²``. On rough rail ``F`` is of
the order of ``|S|²`` (the roughness response passes the same wheel–track
resonance as the sleeper response), so ``|E|`` reads high and scatters.

Three things in the data separate them (physics, not tuning):

* **The band beside the order** (:func:`sideband_floor`): roughness is
  broadband, so the residual (the signal less every extracted order) beside the
  sleeper order holds roughness response of about the density inside the band.
  Two side bands of the order's own bandwidth B, centred
  :data:`SIDEBAND_OFFSET` bandwidths below and above ``f_s`` (their −3 dB edges
  B/2 outside the order's), are filtered out of the residual with the order's
  own envelope filter; with the gain :func:`floor_gain` (how the coupled VKF
  shares a flat density among its orders) each gives a floor, and the lesser of
  their 20 m medians is the floor per bin (:func:`side_floor`). Phase-free and
  local, but on the physics runs not the band's density: 7–70× less where the
  roughness response peaks at ``f_s`` (the wheel–track resonance that makes a
  track respond strongly there), 6–9× more on soft track far above it. A single
  wheel therefore takes it off only where the band's own fluctuation shows at
  least as much.
* **The envelope's own fluctuation** (:func:`inband_floor`): over ≈ 20 m of
  uniform track ``S`` is steady while ``R`` decorrelates every few metres
  (:func:`app.analysis.uncertainty.envelope_correlation`), so the median of
  ``|E(x + δ) − E(x)|²`` at the first zero δ of that correlation measures ``F``
  inside the band. A real change of support reads as floor here (a median
  ignores isolated steps, not steady variation), so it enters the 1-σ only,
  never the amplitude.
* **Two rails** (:func:`two_rail_estimate`): the wheels of one axle run over the
  same sleepers and ballast but over rails with independent roughness, so
  ``Re(E₁ · conj(E₂))`` has the expectation ``|S|²`` (the response common to
  both rails) whatever ``F₁``, ``F₂`` are, and ``E|E_i|² − |S|²`` measures each
  rail's in-band floor.

Estimates (per 25 cm bin)
-------------------------
* single wheel (:func:`single_wheel_estimate`): ``sqrt(max(|E|² − F_side, 0)) / c``;
* two wheels of an axle (:func:`two_rail_estimate`): ``sqrt(max(Re(E₁ conj E₂), 0)) / c``,
  the same value for both wheels;

``c = E[sqrt(X⁺)] / S`` is the square root's bias at low signal-to-roughness
ratio (the power estimate ``X`` is unbiased for the floor taken off, its square
root is not: ``E sqrt(X⁺) < S`` for ``S²/σ ≳ 0.3``).

The 1-σ of each follows from the power model with the floors measured above,
averaged over :data:`FLOOR_WINDOW_LENGTHS` correlation lengths: for two rails the
spread of the estimate (exact moments of the cross product of two complex
Gaussian envelopes, :func:`app.analysis.uncertainty.cross_rail_moments`), for a
single wheel the root mean square error including the floor the side bands miss
(exact Rice moments, :func:`app.analysis.uncertainty.rice_clipped_moments`); of
that, the bias of the floor not taken off and the floor estimate's scatter are
stated apart as shared along the window (``shared``). Segments:
:func:`app.analysis.uncertainty.segment_sd`.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from scipy.ndimage import median_filter
from scipy.signal import butter, sosfiltfilt

from app.analysis.uncertainty import (
    FLOOR_WINDOW_LENGTHS,
    STEP_WIDTH_FACTORS,
    correlation_length,
    correlation_zero,
    cross_rail_moments,
    envelope_response_squared,
    rice_clipped_moments,
    shared_window_m,
)

__all__ = [
    "FLOOR_WINDOW_LENGTHS",
    "SIDEBAND_OFFSET",
    "floor_gain",
    "increment_lag",
    "inband_floor",
    "sideband_floor",
    "side_floor",
    "single_wheel_estimate",
    "smooth_along",
    "two_rail_estimate",
]

#: centre of each side band from f_s, in the order's full -3 dB bandwidths B: the nearest band of
#: width B whose -3 dB edge lies B/2 outside the order's (the residual's notch under the order
#: costs it ≈ 10 % of a flat density, restored by floor_gain)
SIDEBAND_OFFSET = 1.5


def floor_gain(
    filter_order: int = 2,
    offset: float = SIDEBAND_OFFSET,
    multipliers: np.ndarray | None = None,
    bandwidths: np.ndarray | None = None,
    sleeper_row: int = 0,
) -> float:
    """Power in the sleeper order's band over the power its side bands see, for a flat density.

    For a stationary signal the coupled VKF splits the content at a frequency f
    among the orders in proportion to ``w_n(f) = H_n/(1 − H_n) = 1 / ((√2−1)(2(f − f_n)/B_n)^(2q))``
    (the weights of its least-squares problem): order ``n`` takes
    ``G_n = w_n / (1 + Σ_m w_m)``, the residual keeps ``R = 1 / (1 + Σ_m w_m)`` —
    ``H_n`` and ``1 − H_n`` for an order alone, a narrow notch at every wheel
    order, which takes a slice of the side bands and, less, of the sleeper
    order's own band. A side band at ``±offset·B`` sees the residual through
    ``H_s(f ∓ offset·B)``. For a density flat around ``f_s``::

        κ = ∫ G_s(f)² df / ½ Σ_± ∫ R(f)² H_s(f ∓ offset·B)² df

    (1.108 at q = 2, offset 1.5 for the sleeper order alone; 1.28 with the
    default recipe's wheel orders on 0.92 m wheels). ``κ × side-band power`` is
    the floor in the order's band.

    Parameters
    ----------
    filter_order : int
        q of the VKF, 1–3.
    offset : float
        Side-band centre from ``f_s`` in bandwidths (> 0.5).
    multipliers, bandwidths : ndarray, shape (s,), optional
        Every tracked order's frequency and full -3 dB bandwidth per unit speed
        (Hz per m/s: the recipe's ``multipliers`` and ``bandwidth_per_speed``);
        default: the sleeper order alone.
    sleeper_row : int
        Row of the sleeper order in them.
    """
    if filter_order not in STEP_WIDTH_FACTORS:
        raise ValueError(f"filter_order must be 1, 2 or 3, got {filter_order!r}")
    if not (math.isfinite(offset) and offset > 0.5):
        raise ValueError(f"offset must be a number > 0.5 bandwidths, got {offset!r}")
    if multipliers is None or bandwidths is None:
        return _lone_floor_gain(int(filter_order), float(offset))
    mult = np.asarray(multipliers, dtype=np.float64)
    bw = np.asarray(bandwidths, dtype=np.float64)
    if mult.ndim != 1 or bw.shape != mult.shape or not 0 <= sleeper_row < mult.size:
        raise ValueError("multipliers and bandwidths must be 1-D of one length holding sleeper_row")
    if not (np.all(bw > 0) and np.all(np.isfinite(mult))):
        raise ValueError("bandwidths must be > 0 and multipliers finite")
    f0, b0 = float(mult[sleeper_row]), float(bw[sleeper_row])
    # in units of the sleeper bandwidth, around f_s; fine enough for the narrowest order
    step = min(float(bw.min()) / b0 / 40.0, 0.01)
    kappa = np.arange(-(offset + 6.0), offset + 6.0 + step, step)
    rel = (mult - f0) / b0
    widths = bw / b0

    def weight(k: np.ndarray, centre: float, width: float) -> np.ndarray:
        d = (math.sqrt(2.0) - 1.0) * (2.0 * (k - centre) / width) ** (2 * filter_order)
        return 1.0 / np.maximum(d, 1e-300)

    def h(k: np.ndarray, centre: float, width: float) -> np.ndarray:
        return 1.0 / (1.0 + (math.sqrt(2.0) - 1.0) * (2.0 * (k - centre) / width) ** (2 * filter_order))

    total = np.zeros_like(kappa)
    for i in range(mult.size):
        if abs(rel[i]) < offset + 6.0 + 4.0 * widths[i]:
            total += weight(kappa, rel[i], widths[i])
    own = weight(kappa, 0.0, 1.0)
    residual = 1.0 / (1.0 + total)
    inside = np.sum((own * residual) ** 2)
    side = 0.5 * sum(np.sum(residual**2 * h(kappa, sgn * offset, 1.0) ** 2) for sgn in (-1.0, 1.0))
    return float(inside / side)


@lru_cache(maxsize=8)
def _lone_floor_gain(filter_order: int, offset: float) -> float:
    kappa = np.linspace(-40.0, 40.0, 160_001)
    h2 = envelope_response_squared(kappa, filter_order)
    notch = (1.0 - np.sqrt(h2)) ** 2
    side = envelope_response_squared(kappa - offset, filter_order)
    return float(np.sum(h2) / np.sum(notch * side))


def sideband_floor(
    demod: np.ndarray,
    grid_rate: float,
    speed: np.ndarray,
    bandwidth_per_speed: float,
    order_multiplier: float,
    filter_order: int = 2,
    offset: float = SIDEBAND_OFFSET,
    gain: float | None = None,
) -> np.ndarray:
    """Floor of the sleeper order from the residual's side bands, per grid point, (m/s²)².

    Parameters
    ----------
    demod : ndarray, complex, shape (m,)
        The residual mixed down by the sleeper phase and averaged over each grid
        interval (:func:`app.analysis.order_residual.railway_residual` with
        ``demodulate=True``), m/s².
    grid_rate : float
        Rate of the grid, Hz (sample rate / grid step).
    speed : ndarray, shape (m,)
        Absolute speed at the grid points, m/s.
    bandwidth_per_speed : float
        The sleeper order's full -3 dB bandwidth per unit speed, Hz per m/s
        (:attr:`app.analysis.recipe.OrderRecipe.bandwidth_per_speed` of its row).
    order_multiplier : float
        The sleeper order's frequency per unit speed, ``1/d_s``, Hz per m/s.
    filter_order : int
        q of the VKF.
    offset : float
        Side-band centre from ``f_s``, in bandwidths.
    gain : float, optional
        :func:`floor_gain` of the recipe the residual was made with (its wheel
        orders notch the side bands too); default: the sleeper order's alone.

    Returns
    -------
    ndarray, shape (2, m)
        ``gain · |L|²`` and ``gain · |U|²`` with ``L``, ``U`` the peak envelopes of the
        lower and upper side band (the VKF with the order's bandwidth rule, at
        ``f_s ∓ offset·B``): each the floor the order's band would hold if the
        density there were that band's. NaN where there is no room for them: the
        lower band's −3 dB edge below ``f_s / 2`` (track resolutions under ≈ 2 m on
        0.6 m sleepers).

    Notes
    -----
    The grid series holds the residual's content around ``f_s`` at offsets
    ``δf``. The sleeper order's bandwidth is proportional to speed (a fixed
    spatial resolution), so along the travelled distance its envelope filter is
    one fixed zero-phase low-pass, ``H(k) = 1/(1 + (√2−1)(2k/b)^(2q))`` with
    ``b = bandwidth_per_speed`` cycles per metre. The series is resampled onto a
    uniform distance grid, each side band shifted to 0 (``exp(∓i2π·offset·b·x)``)
    and low-passed by a Butterworth filter of order q run forth and back, whose
    squared magnitude is that ``H`` exactly: the order's own filter, without a
    second VKF solve. (Below the bandwidth's floor speed the VKF keeps its
    bandwidth in Hz; those samples do not count for indicators.)
    """
    z = np.asarray(demod)
    v = np.abs(np.asarray(speed, dtype=np.float64))
    if z.ndim != 1 or v.shape != z.shape:
        raise ValueError(f"demod and speed must be 1-D of one length, got {z.shape} and {v.shape}")
    if not (math.isfinite(grid_rate) and grid_rate > 0):
        raise ValueError(f"grid_rate must be > 0 Hz, got {grid_rate!r}")
    if z.size < 4:
        return np.full((2, z.size), np.nan)
    b = float(bandwidth_per_speed)  # cycles per metre: the bandwidth is proportional to speed
    if (offset + 0.5) * b >= 0.5 * float(order_multiplier):
        # no room for the side bands (the lower one would reach below f_s / 2: a resolution under ~2 m
        # on 0.6 m sleepers): no floor from them
        return np.full((2, z.size), np.nan)
    # along the travelled distance the order's filter is one fixed low-pass of the envelope (B = b·v):
    # resample the grid series onto a uniform distance grid, shift each side band to 0 and filter
    dist = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]))]) / grid_rate
    step_m = max(float(np.max(np.diff(dist))) if z.size > 1 else 0.0, 1e-3)
    if dist[-1] < 8.0 * step_m:
        return np.full((2, z.size), np.nan)
    grid = np.arange(0.0, dist[-1], step_m)
    zd = np.interp(grid, dist, z.real) + 1j * np.interp(grid, dist, z.imag)
    # a Butterworth of order q run forth and back: |G|² = 1/(1 + (k/k_c)^(2q)) is the VKF's H exactly
    k_c = 0.5 * b * (math.sqrt(2.0) - 1.0) ** (-1.0 / (2 * filter_order))
    sos = butter(int(filter_order), k_c * 2.0 * step_m, output="sos")
    env = []
    for sign in (-1.0, 1.0):
        shifted = zd * np.exp(-2j * np.pi * sign * offset * b * grid)
        low = sosfiltfilt(sos, shifted.real) + 1j * sosfiltfilt(sos, shifted.imag)
        power = 4.0 * np.abs(low) ** 2  # a side-band component A·cos(…) sits in the grid series as A/2
        env.append(np.interp(dist, grid, power))
    env = np.vstack(env)
    k = floor_gain(filter_order, offset) if gain is None else float(gain)
    return k * env


def _dense(bins: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    b0 = int(bins.min())
    span = int(bins.max()) - b0 + 1
    dense = np.full(span, np.nan, dtype=values.dtype if np.iscomplexobj(values) else np.float64)
    dense[bins - b0] = values
    return dense, bins - b0, span


def smooth_along(bins: np.ndarray, values: np.ndarray, window_m: float, bin_length: float = 0.25) -> np.ndarray:
    """Moving mean over ``window_m`` of track centred on each bin, NaN (and missing bins) ignored.

    Parameters
    ----------
    bins : ndarray of int, shape (n,)
        Unique bin indices (any order).
    values : ndarray, shape (n,)
        Real or complex values; NaN counts as missing.
    window_m : float
        Window length, m (≥ one bin).
    bin_length : float
        m.

    Returns
    -------
    ndarray, shape (n,)
        The mean of the finite values within ``±window_m/2`` of each bin; NaN where none.
    """
    b = np.asarray(bins, dtype=np.int64)
    x = np.asarray(values)
    if b.shape != x.shape or b.ndim != 1:
        raise ValueError(f"bins and values must be 1-D of one length, got {b.shape} and {x.shape}")
    if b.size == 0:
        return x.astype(np.float64 if not np.iscomplexobj(x) else np.complex128)
    half = max(0, int(round(window_m / bin_length / 2.0)))
    dense, pos, span = _dense(b, x)
    ok = np.isfinite(dense)
    vals = np.where(ok, dense, 0)
    csum = np.concatenate([[0], np.cumsum(vals)])
    ccnt = np.concatenate([[0], np.cumsum(ok)])
    lo = np.clip(pos - half, 0, span)
    hi = np.clip(pos + half + 1, 0, span)
    cnt = ccnt[hi] - ccnt[lo]
    tot = csum[hi] - csum[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(cnt > 0, tot / np.maximum(cnt, 1), np.nan)
    return out


def increment_lag(resolution_m: float = 3.0, filter_order: int = 2) -> float:
    """First zero of the envelope correlation, m (4.23 m at 3 m, q = 2): the lag of :func:`inband_floor`."""
    return correlation_zero(resolution_m, filter_order)


def inband_floor(
    bins: np.ndarray,
    envelope: np.ndarray,
    bin_length: float = 0.25,
    resolution_m: float = 3.0,
    filter_order: int = 2,
) -> np.ndarray:
    """The floor inside the order's band from the envelope's fluctuation, (m/s²)², per bin.

    ``median(|E(x + δ/2) − E(x − δ/2)|²) / (2 ln 2)`` over a window of
    :data:`FLOOR_WINDOW_LENGTHS` correlation lengths, δ = :func:`increment_lag`:
    for ``E = S + R`` with ``S`` steady over δ and ``R`` circular Gaussian
    (uncorrelated at δ), the increment is ``R``'s with twice its power and
    exponentially distributed power (median = ln 2 × mean). The median ignores
    isolated steps of ``S`` (a transition touches δ of a 20 m window).

    Parameters
    ----------
    bins : ndarray of int, shape (n,)
        Unique bin indices.
    envelope : ndarray, complex, shape (n,)
        The sleeper order's envelope, bin means, m/s².
    bin_length, resolution_m, filter_order :
        As in :func:`app.analysis.uncertainty.envelope_correlation`.
    """
    b = np.asarray(bins, dtype=np.int64)
    e = np.asarray(envelope, dtype=np.complex128)
    if b.shape != e.shape or b.ndim != 1:
        raise ValueError(f"bins and envelope must be 1-D of one length, got {b.shape} and {e.shape}")
    if b.size == 0:
        return np.zeros(0)
    dense, pos, span = _dense(b, e)
    lag = max(1, int(round(increment_lag(resolution_m, filter_order) / bin_length)))
    h = lag // 2
    inc = np.full(span, np.nan)
    if span > lag:
        inc[h : span - (lag - h)] = np.abs(dense[lag:] - dense[:-lag]) ** 2
    med = _median_dense(inc, _window_m(resolution_m, filter_order), bin_length)
    return med[pos] / (2.0 * math.log(2.0))


def _median_dense(dense: np.ndarray, window_m: float, bin_length: float) -> np.ndarray:
    """Moving median over ``window_m`` of a dense series (NaN: gaps, which take the value before them)."""
    ok = np.isfinite(dense)
    if not np.any(ok):
        return np.full(dense.size, np.nan)
    idx = np.where(ok, np.arange(dense.size), 0)
    np.maximum.accumulate(idx, out=idx)
    first = int(np.argmax(ok))
    idx[:first] = first
    win = max(1, int(round(window_m / bin_length)))
    return median_filter(dense[idx], size=win, mode="nearest")


def side_floor(bins: np.ndarray, floor: np.ndarray, bin_length: float = 0.25, resolution_m: float = 3.0,
               filter_order: int = 2) -> np.ndarray:
    """The floor under the order from its two side bands, (m/s²)², per bin.

    Each side band's floor (:func:`sideband_floor`) is taken as the moving median
    over :data:`FLOOR_WINDOW_LENGTHS` correlation lengths divided by ln 2 (a
    circular Gaussian band's power is exponentially distributed: median = ln 2 ×
    mean). A median, not a mean: a step of the sleeper response (a stiffness
    change) or an impact (a weld) spills its transient into the side bands over a
    few metres; the median of a 20 m window ignores it, as it should: that is
    no floor under the order. Then the lesser of the two: where the roughness
    response peaks at ``f_s`` the band holds more than either side, on the
    response's flank (``f_s`` above or below the resonance) about their
    log-linear interpolation, which their arithmetic mean overshoots. The lesser
    is biased low by the two estimates' own scatter (≈ −13 % of a flat floor over
    20 m): a conservative floor.

    Parameters
    ----------
    bins : ndarray of int, shape (n,)
    floor : ndarray, shape (2, n)
        Bin means of the lower and upper side band's floor, (m/s²)².
    bin_length, resolution_m, filter_order :
        The run's binning and track-order settings.
    """
    b = np.asarray(bins, dtype=np.int64)
    sides = np.asarray(floor, dtype=np.float64)
    if b.ndim != 1 or sides.shape != (2, b.size):
        raise ValueError(f"floor must have shape (2, {b.size}) for {b.size} bins, got {sides.shape}")
    if b.size == 0:
        return np.zeros(0)
    w = _window_m(resolution_m, filter_order)
    out = []
    for side in sides:
        dense, pos, _ = _dense(b, side)
        out.append(_median_dense(dense, w, bin_length)[pos] / math.log(2.0))
    return np.maximum(np.nan_to_num(np.minimum(out[0], out[1])), 0.0)


def _window_m(resolution_m: float, filter_order: int) -> float:
    return shared_window_m(resolution_m, filter_order)


def single_wheel_estimate(
    bins: np.ndarray,
    power: np.ndarray,
    floor: np.ndarray,
    envelope: np.ndarray,
    bin_length: float = 0.25,
    resolution_m: float = 3.0,
    filter_order: int = 2,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Floor-corrected sleeper amplitude of one wheel, its 1-σ and the shared part of it, per bin, m/s².

    Parameters
    ----------
    bins : ndarray of int, shape (n,)
    power : ndarray, shape (n,)
        Bin means of ``|E|²``, (m/s²)².
    floor : ndarray, shape (2, n)
        Bin means of the floor from the lower and the upper side band
        (:func:`sideband_floor`), (m/s²)².
    envelope : ndarray, complex, shape (n,)
        Bin means of ``E``, m/s².
    bin_length, resolution_m, filter_order :
        The run's binning and track-order settings.

    Returns
    -------
    amp : ndarray
        ``sqrt(max(X, 0)) / c``: ``X = power − F_side`` with ``F_side`` the floor of
        :func:`side_floor` (over :data:`FLOOR_WINDOW_LENGTHS` correlation lengths:
        one bin's side band scatters as much as the floor itself, and the floor's
        density changes with the track on the scale of its sections),
        ``c = E[sqrt(X⁺)] / S``
        the square root's bias for that floor (exact for ``|S + R|²``,
        :func:`app.analysis.uncertainty.rice_clipped_moments`; ``S²`` the local mean of ``X``).
    sd : ndarray
        Root mean square error of ``amp`` for ``|E|² = |S + R|²`` with ``E|R|² = F``, the
        in-band floor (:func:`inband_floor`, at least ``F_side``): what the side bands
        miss, ``F − F_side``, stays in ``amp`` as a bias and counts; ``S²`` is the local
        mean of ``X`` less it. The averaged side bands' own scatter (``W/ℓ`` looks)
        adds ``(F_side / (2 amp))² ℓ/(2W)``.
    shared : ndarray
        The part of ``sd`` shared along the floor window ``W``
        (:func:`app.analysis.uncertainty.shared_correlation`): the bias the floor
        not taken off leaves, ``E[amp] − S`` (the same for every bin whose window
        sees the same floor), and the averaged side bands' scatter; the rest of
        ``sd`` is the envelope's broadband part. :func:`app.analysis.uncertainty.segment_sd`
        takes it as ``shared``.
    """
    b = np.asarray(bins, dtype=np.int64)
    p = np.asarray(power, dtype=np.float64)
    sides = np.asarray(floor, dtype=np.float64)
    e = np.asarray(envelope, dtype=np.complex128)
    if not (b.shape == p.shape == e.shape) or b.ndim != 1 or sides.shape != (2, b.size):
        raise ValueError("bins, power and envelope must be 1-D of one length n, floor of shape (2, n)")
    if b.size == 0:
        return p.copy(), p.copy(), p.copy()
    w = _window_m(resolution_m, filter_order)
    f_inc = np.nan_to_num(inband_floor(b, e, bin_length, resolution_m, filter_order))
    # the side bands' floor is taken off only where it is no more than the band's own fluctuation
    # shows: beyond, their density is evidently not the band's (a dip of the response at f_s)
    f_side_w = side_floor(b, sides, bin_length, resolution_m, filter_order)
    f_side_w = np.where(f_side_w <= f_inc, f_side_w, 0.0)
    x = p - f_side_w
    amp = np.sqrt(np.maximum(x, 0.0))
    amp[~np.isfinite(p)] = np.nan
    f_in = np.maximum(f_inc, f_side_w)
    missed = f_in - f_side_w
    looks = w / correlation_length(resolution_m, filter_order)
    x_w = np.maximum(np.nan_to_num(smooth_along(b, x, w, bin_length)), 0.0)
    # the square root's own bias for the floor taken off: E sqrt((|S + R|² − F)⁺) / S, E|R|² = F = F_side
    m1, _ = rice_clipped_moments(x_w, f_side_w, f_side_w)
    root = np.sqrt(x_w)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.where(root > 0, m1 / np.where(root > 0, root, 1.0), 1.0)
    c = np.where(np.isfinite(c) & (c > 0), c, 1.0)
    amp = amp / c
    # the 1-σ: the whole in-band floor F_in (what the side bands miss stays in X as a bias), and the
    # averaged side bands' own scatter
    s2 = np.maximum(x_w - missed, 0.0)
    m1, m2 = rice_clipped_moments(s2, f_in, f_side_w)
    s = np.sqrt(s2)
    mse = m2 / c**2 - 2.0 * s * m1 / c + s2
    with np.errstate(invalid="ignore", divide="ignore"):
        floor_var = np.where(amp > 0, (0.5 / np.where(amp > 0, amp, 1.0)) ** 2 * 0.5 * f_side_w**2 / looks, 0.0)
    sd = np.sqrt(np.maximum(mse, 0.0) + floor_var)
    # shared along the window: the bias of the floor not taken off, and the floor estimate's own scatter
    bias = m1 / c - s
    shared = np.minimum(np.sqrt(bias**2 + floor_var), sd)
    sd[~np.isfinite(amp)] = np.nan
    shared[~np.isfinite(amp)] = np.nan
    return amp, sd, shared


def two_rail_estimate(
    bins: np.ndarray,
    cross: np.ndarray,
    power: np.ndarray,
    power_other: np.ndarray,
    bin_length: float = 0.25,
    resolution_m: float = 3.0,
    filter_order: int = 2,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sleeper amplitude common to the two rails of an axle, its 1-σ and the shared part of it, per bin, m/s².

    Parameters
    ----------
    bins : ndarray of int, shape (n,)
    cross : ndarray, shape (n,)
        Bin means of ``Re(E · conj(E_other))``, (m/s²)²: the two wheels' sleeper
        envelopes on the same bins (same axle, same phase reference).
    power, power_other : ndarray, shape (n,)
        Bin means of ``|E|²`` and ``|E_other|²``, (m/s²)².
    bin_length, resolution_m, filter_order :
        The run's binning and track-order settings.

    Returns
    -------
    amp : ndarray
        ``sqrt(max(X, 0)) / c`` with ``X`` = ``cross`` and ``c = E[sqrt(X⁺)] / S``
        (``c → 1`` where the roughness is small against the sleeper response).
    sd : ndarray
        The spread of ``amp``: ``X = Re((S + R₁) conj(S + R₂))`` with independent
        circular Gaussian ``R_i`` of power ``F_i``, the local mean of ``|E_i|² − X``
        (each rail's in-band floor), ``S²`` the local mean of ``X``; exact moments
        (:func:`app.analysis.uncertainty.cross_rail_moments`).
    shared : ndarray
        0: ``X`` is unbiased whatever the floors, so no floor error is shared
        along the track (the local estimates of ``S²`` and ``F_i`` set ``c`` and
        ``sd`` only).

    Notes
    -----
    The same for either wheel of the axle (``X`` and ``σ`` are symmetric).
    """
    b = np.asarray(bins, dtype=np.int64)
    x = np.asarray(cross, dtype=np.float64)
    p1 = np.asarray(power, dtype=np.float64)
    p2 = np.asarray(power_other, dtype=np.float64)
    if not (b.shape == x.shape == p1.shape == p2.shape) or b.ndim != 1:
        raise ValueError("bins, cross, power and power_other must be 1-D of one length")
    raw = np.sqrt(np.maximum(x, 0.0))
    raw[~np.isfinite(x)] = np.nan
    if b.size == 0:
        return raw, raw.copy(), raw.copy()
    w = _window_m(resolution_m, filter_order)
    f1 = np.maximum(np.nan_to_num(smooth_along(b, p1 - x, w, bin_length)), 0.0)
    f2 = np.maximum(np.nan_to_num(smooth_along(b, p2 - x, w, bin_length)), 0.0)
    s2 = np.maximum(np.nan_to_num(smooth_along(b, x, w, bin_length)), 0.0)
    mean_sqrt, mean_pos = cross_rail_moments(s2, f1, f2)
    root = np.sqrt(s2)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.where(root > 0, mean_sqrt / np.where(root > 0, root, 1.0), 1.0)
    c = np.where(np.isfinite(c) & (c > 0), c, 1.0)
    amp = raw / c
    spread = np.sqrt(np.maximum(mean_pos - mean_sqrt**2, 0.0))
    sd = spread / c
    sd[~np.isfinite(raw)] = np.nan
    shared = np.where(np.isfinite(raw), 0.0, np.nan)
    return amp, sd, shared
