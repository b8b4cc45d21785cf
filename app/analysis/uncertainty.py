"""Uncertainty of the sleeper-passage amplitude: the power model of a bin, and segments from bins.

Two pure building blocks, used by :mod:`app.analysis.roughness` (per 25 cm bin)
and by whoever aggregates bins to segments (:func:`app.analysis.aggregate.aggregate_profile`,
the change tests and tiers of the condition store):

* **Along-track correlation.** The track orders are extracted by the VKF with a
  bandwidth proportional to speed, i.e. a fixed spatial resolution Δx
  (``track_resolution_m``, :func:`app.analysis.recipe.track_bandwidth_per_speed`).
  For a stationary order the VKF is the zero-phase low-pass
  ``H(k) = 1 / (1 + (√2−1)(2k/b)^(2q))`` of the complex envelope, ``b = c_q/Δx``
  cycles per m. Whatever broadband response (rail roughness, noise) falls in the
  order's band therefore reaches the envelope as a process whose along-track
  autocorrelation is the inverse Fourier transform of ``H²``
  (:func:`envelope_correlation`): bins 25 cm apart are almost the same
  measurement, bins more than ≈ 1.4 Δx apart are independent. A mean over a
  segment of length L holds about ``L / ℓ`` independent looks, with the
  correlation length ``ℓ = ∫ρ = 1 / ∫H²`` (:func:`correlation_length`: 4.0 m at
  the default 3 m, q = 2): that, not the number of sleeper bays or of bins, sets
  how fast averaging helps.
* **Power model of one bin.** An unbiased power estimate ``X`` of the sleeper
  component (``E[X] = S²``) with a Gaussian error of σ (m²/s⁴) gives the
  amplitude ``sqrt(max(X, 0))``, whose mean and spread follow in closed form
  (:func:`clipped_sqrt_moments`); this is how an amplitude's bias at low
  signal-to-roughness ratio and its 1-σ are computed. For the cross product of
  two rails, ``X = Re((S + R₁) conj(S + R₂))`` with independent circular
  Gaussian ``R₁``, ``R₂``, the moments are exact (:func:`cross_rail_moments`):
  ``X`` is skewed and heavier-tailed than a Gaussian of its variance.
* **Shared part.** Part of a bin's error is not the envelope's broadband part
  but an error of a quantity estimated over a window of :data:`FLOOR_WINDOW_LENGTHS`
  correlation lengths (≈ 20 m: a single wheel's floor that cannot be taken off,
  the floor estimate's own scatter). It is shared by every bin in reach of the
  window: its correlation is that of a moving mean over the window, the
  triangle ``(1 − |Δ|/W)⁺`` (:func:`shared_correlation`).

:func:`segment_sd` is the one rule for the 1-σ of a segment's mean from the 1-σ
of its bins (and, where stated, the shared part of it).
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
from numpy.polynomial.hermite_e import hermegauss
from scipy.special import i0e, ndtr, pbdv

if TYPE_CHECKING:  # scipy.interpolate loads with the first table (≈ 0.2 s of every API process otherwise)
    from scipy.interpolate import RegularGridInterpolator

__all__ = [
    "FLOOR_WINDOW_LENGTHS",
    "STEP_WIDTH_FACTORS",
    "clipped_sqrt_moments",
    "cross_rail_moments",
    "rice_clipped_moments",
    "correlation_length",
    "correlation_zero",
    "envelope_correlation",
    "envelope_response_squared",
    "segment_sd",
    "shared_correlation",
    "shared_window_m",
]

#: c_q of :data:`app.analysis.recipe.STEP_WIDTH_FACTOR` (10–90 % width × bandwidth), repeated
#: here so that this module imports nothing of the project; a test checks they agree
STEP_WIDTH_FACTORS: dict[int, float] = {1: 2.0 * math.log(5.0) / math.pi * math.sqrt(math.sqrt(2.0) - 1.0),
                                        2: 0.7205, 3: 0.7672}
#: the floors and the local signal power of the 1-σ model are estimated over this many correlation
#: lengths (≈ 20 m at 3 m resolution): ≈ 5 independent looks, local to a stiffness section; what is
#: estimated over it is an error shared along it (:func:`shared_correlation`)
FLOOR_WINDOW_LENGTHS = 5.0
#: spectral grid of the tabulated correlation, in units of the bandwidth b
_DK = 1.0 / 512.0
_NK = 1 << 17
#: lags beyond this many resolutions are treated as uncorrelated (|ρ| < 1e-4 there for q = 1..3)
_MAX_LAG_RESOLUTIONS = 8.0
#: above this signal-to-noise ratio mu/sigma the moments use their asymptotic series
_T_ASYMPTOTIC = 25.0


def _check_q(filter_order: int) -> int:
    if filter_order not in STEP_WIDTH_FACTORS:
        raise ValueError(f"filter_order must be 1, 2 or 3, got {filter_order!r}")
    return int(filter_order)


def _check_resolution(resolution_m: float) -> float:
    try:
        r = float(resolution_m)
    except (TypeError, ValueError):
        raise ValueError(f"resolution_m must be a number > 0 m, got {resolution_m!r}") from None
    if not (math.isfinite(r) and r > 0):
        raise ValueError(f"resolution_m must be a number > 0 m, got {resolution_m!r}")
    return r


def _response_squared(kappa: np.ndarray, q: int) -> np.ndarray:
    """``H²`` of the VKF's envelope low-pass at ``kappa = k / b`` (b the full -3 dB bandwidth)."""
    return (1.0 / (1.0 + (math.sqrt(2.0) - 1.0) * (2.0 * kappa) ** (2 * q))) ** 2


@lru_cache(maxsize=3)
def _correlation_table(q: int) -> tuple[np.ndarray, float]:
    """``g(s)``: ρ at the lag ``s · Δx`` (tabulated by FFT of ``H²``), and the step of ``s``."""
    kappa = (np.arange(_NK) - _NK // 2) * _DK
    spectrum = _response_squared(kappa, q)
    acf = np.fft.fftshift(np.fft.ifft(np.fft.ifftshift(spectrum))).real
    acf = acf[_NK // 2 :] / acf[_NK // 2]
    # lag of one step in units of 1/b is 1/(N dκ); in resolutions Δx = c_q / b: / c_q
    ds = 1.0 / (_NK * _DK * STEP_WIDTH_FACTORS[q])
    n = int(math.ceil(_MAX_LAG_RESOLUTIONS / ds)) + 1
    table = acf[:n].copy()
    table.setflags(write=False)
    return table, ds


def envelope_correlation(lag_m: np.ndarray | float, resolution_m: float = 3.0, filter_order: int = 2) -> np.ndarray:
    """Along-track autocorrelation of the broadband part of a track order's envelope.

    Parameters
    ----------
    lag_m : array_like
        Distance between two points of the profile, m (sign ignored).
    resolution_m : float, optional
        The track orders' spatial resolution Δx (``track_resolution_m``), m. Default 3.
    filter_order : int, optional
        q of the VKF, 1–3. Default 2.

    Returns
    -------
    ndarray
        ρ (1 at lag 0, 0 beyond 8 Δx), shape of ``lag_m``.

    Notes
    -----
    ``ρ(Δ) = ∫ H(k)² cos(2πkΔ) dk / ∫ H(k)² dk`` with ``H`` the envelope low-pass
    of the module notes: the correlation of a white (or locally flat) input seen
    through the order's filter. It has small negative side lobes (q ≥ 2).
    """
    q = _check_q(filter_order)
    res = _check_resolution(resolution_m)
    lag = np.abs(np.asarray(lag_m, dtype=np.float64)) / res
    table, ds = _correlation_table(q)
    s = np.arange(table.size) * ds
    return np.interp(lag, s, table, right=0.0)


def envelope_response_squared(kappa: np.ndarray, filter_order: int = 2) -> np.ndarray:
    """``H²`` of the VKF's envelope low-pass at ``kappa`` = frequency offset / full -3 dB bandwidth."""
    return _response_squared(np.asarray(kappa, dtype=np.float64), _check_q(filter_order))


def correlation_zero(resolution_m: float = 3.0, filter_order: int = 2) -> float:
    """First lag at which :func:`envelope_correlation` reaches 0, m (4.23 m at 3 m, q = 2)."""
    q = _check_q(filter_order)
    res = _check_resolution(resolution_m)
    table, ds = _correlation_table(q)
    return float(int(np.argmax(table <= 0.0)) * ds * res)


def correlation_length(resolution_m: float = 3.0, filter_order: int = 2) -> float:
    """``ℓ = ∫ρ(Δ) dΔ``, m: a mean over L ≫ ℓ has the variance of ``L / ℓ`` independent bins.

    Equals ``1 / ∫H(k)² dk`` = ``Δx / (c_q ∫H(κ)² dκ)``: 4.01 m at Δx = 3 m, q = 2.
    """
    q = _check_q(filter_order)
    res = _check_resolution(resolution_m)
    return res / (STEP_WIDTH_FACTORS[q] * _response_integral(q))


@lru_cache(maxsize=3)
def _response_integral(q: int) -> float:
    """``∫H(κ)² dκ`` of the envelope low-pass (on the grid of :func:`_correlation_table`; 10 ms a call, and the
    places and the store ask for it per run and per wheel)."""
    kappa = (np.arange(_NK) - _NK // 2) * _DK
    return float(np.sum(_response_squared(kappa, q)) * _DK)


def shared_window_m(resolution_m: float = 3.0, filter_order: int = 2) -> float:
    """Length of the window the floors are estimated over, m: :data:`FLOOR_WINDOW_LENGTHS` ×
    :func:`correlation_length` (20.0 m at 3 m, q = 2)."""
    return FLOOR_WINDOW_LENGTHS * correlation_length(resolution_m, filter_order)


def shared_correlation(lag_m: np.ndarray | float, resolution_m: float = 3.0, filter_order: int = 2) -> np.ndarray:
    """Along-track correlation of the shared part of a bin's error: ``(1 − |Δ|/W)⁺``.

    Parameters
    ----------
    lag_m : array_like
        Distance between two bins, m (sign ignored).
    resolution_m, filter_order : optional
        As in :func:`envelope_correlation`; ``W`` = :func:`shared_window_m`.

    Returns
    -------
    ndarray
        ρ, shape of ``lag_m``.

    Notes
    -----
    A quantity estimated as a moving mean over ``W`` of a process that
    decorrelates within much less than ``W`` has the correlation of two windows'
    overlap, the triangle; the floors' moving medians share it closely enough
    (the same overlap of the looks they rank).
    """
    w = shared_window_m(resolution_m, filter_order)
    lag = np.abs(np.asarray(lag_m, dtype=np.float64))
    return np.maximum(1.0 - lag / w, 0.0)


def clipped_sqrt_moments(mu: np.ndarray | float, sigma: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``sqrt(max(X, 0))`` and of ``max(X, 0)`` for ``X ~ N(mu, sigma²)``.

    Parameters
    ----------
    mu : array_like
        Expected power, e.g. (m/s²)².
    sigma : array_like
        Standard deviation of the power estimate, same unit, ≥ 0 (broadcast with ``mu``).

    Returns
    -------
    mean_sqrt : ndarray
        ``E[sqrt(X⁺)]`` (the unit of an amplitude).
    mean_pos : ndarray
        ``E[X⁺]``.

    Notes
    -----
    ``E[X⁺^ν] = Γ(ν+1) σ^ν e^(−t²/4) D_(−ν−1)(−t) / √(2π)`` with ``t = μ/σ`` and ``D`` the
    parabolic cylinder function; ν = 1/2 for the amplitude. Above ``t = 25`` the
    series ``√μ (1 − σ²/(8μ²) − 15σ⁴/(128μ⁴))`` is used; ``σ = 0`` gives ``√max(μ, 0)``.
    """
    mu_b, sig_b = np.broadcast_arrays(np.asarray(mu, dtype=np.float64), np.asarray(sigma, dtype=np.float64))
    if np.any(sig_b < 0):
        raise ValueError("sigma must be >= 0")
    shape = mu_b.shape
    mu_a, sig_a = mu_b.reshape(-1), sig_b.reshape(-1)
    mean_sqrt = np.sqrt(np.maximum(mu_a, 0.0))
    mean_pos = np.maximum(mu_a, 0.0)
    noisy = (sig_a > 0) & np.isfinite(mu_a) & np.isfinite(sig_a)
    if np.any(noisy):
        m, s = mu_a[noisy], sig_a[noisy]
        t = m / s
        pos = s * np.exp(-0.5 * t * t) / math.sqrt(2.0 * math.pi) + m * ndtr(t)
        root = np.empty_like(t)
        high = t > _T_ASYMPTOTIC
        th = t[high]
        root[high] = np.sqrt(m[high]) * (1.0 - 1.0 / (8.0 * th**2) - 15.0 / (128.0 * th**4))
        low = ~high
        tl = np.maximum(t[low], -38.0)  # below, E is < 1e-300: zero
        d = pbdv(-1.5, -tl)[0]
        root[low] = (math.sqrt(math.pi) / 2.0) * np.sqrt(s[low]) * np.exp(-0.25 * tl * tl) * d / math.sqrt(2.0 * math.pi)
        mean_sqrt[noisy] = root
        mean_pos[noisy] = pos
    return mean_sqrt.reshape(shape), mean_pos.reshape(shape)


#: grid of the tabulated moments of the single-wheel power: log10(S²/F) and threshold/F
_LOG_SNR = np.linspace(-4.0, 5.0, 361)
_THRESHOLD = np.linspace(0.0, 2.0, 81)


@lru_cache(maxsize=1)
def _rice_tables() -> tuple[RegularGridInterpolator, RegularGridInterpolator]:
    """``E[sqrt((P − T)⁺)] / √F`` and ``E[(P − T)⁺] / F`` over (log10 S²/F, T/F), P = |S + R|², R ~ CN(0, F)."""
    from scipy.interpolate import RegularGridInterpolator

    nu = np.sqrt(2.0 * 10.0 ** _LOG_SNR)  # |S| in units of sqrt(F/2): r = |E| / sqrt(F/2) is Rice(nu, 1)
    h1 = np.empty((nu.size, _THRESHOLD.size))
    h2 = np.empty_like(h1)
    for i, v in enumerate(nu):
        r = np.linspace(max(v - 9.0, 0.0), v + 9.0, 721)
        pdf = r * np.exp(-0.5 * (r - v) ** 2) * i0e(r * v)
        wts = pdf * (r[1] - r[0])
        wts /= wts.sum()
        power = 0.5 * r * r  # P / F
        excess = np.maximum(power[None, :] - _THRESHOLD[:, None], 0.0)
        h1[i] = np.sqrt(excess) @ wts
        h2[i] = excess @ wts
    opts = {"bounds_error": False, "fill_value": None}
    return (RegularGridInterpolator((_LOG_SNR, _THRESHOLD), h1, **opts),
            RegularGridInterpolator((_LOG_SNR, _THRESHOLD), h2, **opts))


def rice_clipped_moments(
    s2: np.ndarray | float, floor: np.ndarray | float, threshold: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``sqrt(max(P − T, 0))`` and of ``max(P − T, 0)`` for ``P = |S + R|²``, ``R ~ CN(0, F)``.

    The power of one wheel's envelope (the sleeper response ``S`` plus a circular
    Gaussian floor of power ``F``) less a floor ``T`` taken off: exact (Rice
    distribution of ``|S + R|``, tabulated over ``S²/F`` = 10⁻⁴ … 10⁵ and
    ``T/F`` = 0 … 2), unlike the Gaussian model of :func:`clipped_sqrt_moments`,
    which misses the skew of a single wheel's power at ``S²/F ≲ 3``.

    Parameters
    ----------
    s2 : array_like
        ``S²``, e.g. (m/s²)², ≥ 0.
    floor : array_like
        ``F``, same unit, ≥ 0.
    threshold : array_like
        ``T``, same unit, ≥ 0.

    Returns
    -------
    mean_sqrt, mean_pos : ndarray
        ``E[sqrt((P − T)⁺)]`` and ``E[(P − T)⁺]``; ``F = 0`` gives
        ``sqrt(max(S² − T, 0))`` and ``max(S² − T, 0)``; above ``S²/F = 10⁵`` the
        floor's effect is taken as ``S² + F − T`` (its mean).
    """
    a, f, t = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (s2, floor, threshold)))
    shape = a.shape
    a, f, t = (np.maximum(v.reshape(-1), 0.0) for v in (a, f, t))
    mean_pos = np.maximum(a + f - t, 0.0)
    mean_sqrt = np.sqrt(mean_pos)
    noisy = (f > 0) & np.isfinite(a) & np.isfinite(f) & np.isfinite(t)
    with np.errstate(divide="ignore"):
        log_snr = np.log10(np.where(noisy, a / np.where(f > 0, f, 1.0), 1.0))
    table = noisy & (log_snr <= _LOG_SNR[-1]) & (t / np.where(f > 0, f, 1.0) <= _THRESHOLD[-1])
    if np.any(table):
        h1, h2 = _rice_tables()
        pts = np.column_stack([np.maximum(log_snr[table], _LOG_SNR[0]), t[table] / f[table]])
        mean_sqrt[table] = np.maximum(h1(pts), 0.0) * np.sqrt(f[table])
        mean_pos[table] = np.maximum(h2(pts), 0.0) * f[table]
    return mean_sqrt.reshape(shape), mean_pos.reshape(shape)


#: Gauss–Hermite nodes per axis of the rail-1 floor in :func:`cross_rail_moments`' table (≤ 0.3 %)
_CROSS_NODES = 16
#: grid of the tabulated cross-rail moments: log10(S² / sqrt(F₁F₂)) and |log10(F₁/F₂)|
_CROSS_LOG_U = np.linspace(-3.0, 3.0, 61)
_CROSS_LOG_R = np.linspace(0.0, 3.0, 13)


def _cross_direct(s2: np.ndarray, f1: np.ndarray, f2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The moments of :func:`cross_rail_moments` by quadrature (conditional on ``R₁``, ``X`` is Gaussian)."""
    z, w = hermegauss(_CROSS_NODES)
    w = w / w.sum()
    re = np.repeat(z, z.size)[None, :] * np.sqrt(f1 / 2.0)[:, None]
    im = np.tile(z, z.size)[None, :] * np.sqrt(f1 / 2.0)[:, None]
    ww = np.outer(w, w).ravel()
    root = np.sqrt(s2)[:, None]
    mu = root * (root + re)  # Re((S + R₁) S)
    sigma = np.sqrt(((root + re) ** 2 + im**2) * f2[:, None] / 2.0)  # |S + R₁| sqrt(F₂/2)
    m1, m2 = clipped_sqrt_moments(mu, sigma)
    return m1 @ ww, m2 @ ww


@lru_cache(maxsize=1)
def _cross_tables() -> tuple[RegularGridInterpolator, RegularGridInterpolator]:
    """``log E[sqrt(X⁺)] / g^½`` and ``log E[X⁺] / g`` over (log10 u, |log10 r|), ``g = sqrt(F₁F₂)``."""
    from scipy.interpolate import RegularGridInterpolator

    lu, lr = np.meshgrid(_CROSS_LOG_U, _CROSS_LOG_R, indexing="ij")
    u, r = 10.0 ** lu.ravel(), 10.0 ** lr.ravel()
    m1, m2 = _cross_direct(u, np.sqrt(r), 1.0 / np.sqrt(r))
    opts = {"bounds_error": False, "fill_value": None}
    shape = lu.shape
    return (RegularGridInterpolator((_CROSS_LOG_U, _CROSS_LOG_R), np.log(m1).reshape(shape), **opts),
            RegularGridInterpolator((_CROSS_LOG_U, _CROSS_LOG_R), np.log(m2).reshape(shape), **opts))


def cross_rail_moments(
    s2: np.ndarray | float, floor_1: np.ndarray | float, floor_2: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``sqrt(max(X, 0))`` and of ``max(X, 0)`` for ``X = Re((S + R₁) conj(S + R₂))``.

    The cross product of the two wheels' envelopes of an axle: the common
    sleeper response ``S`` plus each rail's broadband part ``R_i``, independent
    circular Gaussian of power ``F_i`` (``E X = S²``, ``var X = S²(F₁ + F₂)/2 +
    F₁F₂/2``). Exact, unlike :func:`clipped_sqrt_moments` of a Gaussian of that
    variance (which puts ``E sqrt(X⁺)`` 5 % too high at ``S² ≈ 0.7 F``): given ``R₁``,
    ``X`` is Gaussian with mean ``S² + S Re R₁`` and variance ``|S + R₁|² F₂/2``;
    the mean over ``R₁`` by Gauss–Hermite quadrature, tabulated over
    ``u = S²/sqrt(F₁F₂)`` = 10⁻³ … 10³ and ``F₁/F₂`` = 10⁻³ … 10³ (symmetric).

    Parameters
    ----------
    s2 : array_like
        ``S²``, e.g. (m/s²)², ≥ 0.
    floor_1, floor_2 : array_like
        ``F₁``, ``F₂``, same unit, ≥ 0.

    Returns
    -------
    mean_sqrt, mean_pos : ndarray
        ``E[sqrt(X⁺)]`` and ``E[X⁺]``. Where a floor is 0, ``X`` is Gaussian and
        :func:`clipped_sqrt_moments` is exact; beyond the table (``u > 10³``, or one
        floor over 10³ times the other) the Gaussian model is used (there ``X`` is
        dominated by its Gaussian terms); below ``u = 10⁻³`` ``S`` no longer counts
        and the table's edge is used.
    """
    a, f1, f2 = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (s2, floor_1, floor_2)))
    shape = a.shape
    a, f1, f2 = (np.maximum(v.reshape(-1), 0.0) for v in (a, f1, f2))
    g = np.sqrt(f1 * f2)
    ok = (g > 0) & np.isfinite(a) & np.isfinite(g)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_u = np.log10(np.where(ok, np.maximum(a, 0.0) / np.where(ok, g, 1.0), 1.0))
        log_r = np.abs(np.log10(np.where(ok, f1 / np.where(ok, f2, 1.0), 1.0)))
    table = ok & (log_u <= _CROSS_LOG_U[-1]) & (log_r <= _CROSS_LOG_R[-1])
    mean_sqrt, mean_pos = np.sqrt(a), a.copy()
    gauss = ~table
    if np.any(gauss):
        sigma = np.sqrt(a[gauss] * (f1[gauss] + f2[gauss]) / 2.0 + f1[gauss] * f2[gauss] / 2.0)
        mean_sqrt[gauss], mean_pos[gauss] = clipped_sqrt_moments(a[gauss], sigma)
    if np.any(table):
        h1, h2 = _cross_tables()
        pts = np.column_stack([np.maximum(log_u[table], _CROSS_LOG_U[0]), log_r[table]])
        mean_sqrt[table] = np.exp(h1(pts)) * np.sqrt(g[table])
        mean_pos[table] = np.exp(h2(pts)) * g[table]
    return mean_sqrt.reshape(shape), mean_pos.reshape(shape)


def segment_sd(
    bins: np.ndarray,
    sd: np.ndarray,
    level_m: float,
    bin_length: float = 0.25,
    resolution_m: float = 3.0,
    filter_order: int = 2,
    shared: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """1-σ of the mean of every segment from the 1-σ of its bins, errors correlated along the track.

    Parameters
    ----------
    bins : array_like of int
        (n,) bin indices ``floor(track_m / bin_length)`` of one wheel's profile, unique.
    sd : array_like of float
        (n,) 1-σ of each bin's value (e.g. ``sleeper_amp_sd``, m/s²); NaN: the bin has no value.
    level_m : float
        Segment length, m (a multiple of ``bin_length``); segment ``g`` of bin ``b`` is
        ``floor(b · bin_length / level_m)``.
    bin_length : float, optional
        m (default 0.25).
    resolution_m, filter_order : optional
        The track orders' resolution (m) and q of the run's processing settings
        (defaults 3 m, 2): they set the along-track correlation (:func:`envelope_correlation`).
    shared : array_like of float, optional
        (n,) the part of each bin's 1-σ that is shared along the floor window (e.g.
        ``sleeper_amp_sd_shared``, ≤ ``sd``; NaN or absent: none): it correlates as
        :func:`shared_correlation`, the rest, ``sqrt(sd² − shared²)``, as
        :func:`envelope_correlation`.

    Returns
    -------
    segments : ndarray of int
        Segment indices that hold at least one bin with a finite ``sd``, sorted.
    sd_mean : ndarray
        1-σ of the mean of the segment's bins (the bins with a finite ``sd``),
        ``sqrt(Σ_i Σ_j sd_i sd_j ρ(|b_i − b_j| · bin_length)) / n``, same unit as ``sd``.

    Raises
    ------
    ValueError
        If shapes differ, ``bins`` are not unique integers, or a length is not > 0.

    Notes
    -----
    The rule treats a bin's error as the envelope's broadband part (roughness
    response, noise) seen through the order's filter, plus the stated shared part.
    Independent bins would give
    ``sd / √n``; correlated ones give about ``sd · √(ℓ / L)`` for a segment of length
    ``L ≫ ℓ`` (:func:`correlation_length`), and ``sd`` for ``L ≪ ℓ``.
    """
    b = np.asarray(bins)
    s = np.asarray(sd, dtype=np.float64)
    if b.ndim != 1 or s.shape != b.shape:
        raise ValueError(f"bins and sd must be 1-D of one length, got {b.shape} and {s.shape}")
    if b.size and b.dtype.kind not in "iu":
        raise ValueError(f"bins must be integers, got dtype {b.dtype}")
    bl = _check_resolution(bin_length)
    level = _check_resolution(level_m)
    k = int(round(level / bl))
    if k < 1 or abs(level / bl - k) > 1e-9 * max(level / bl, 1.0):
        raise ValueError(f"level_m must be a positive integer multiple of bin_length={bl} m, got {level_m!r}")
    if shared is None:
        sh = np.zeros_like(s)
    else:
        sh = np.asarray(shared, dtype=np.float64)
        if sh.shape != s.shape:
            raise ValueError(f"shared must have the shape of sd {s.shape}, got {sh.shape}")
        sh = np.where(np.isfinite(sh), np.maximum(sh, 0.0), 0.0)
    ok = np.isfinite(s)
    b, s, sh = b[ok].astype(np.int64), s[ok], sh[ok]
    if b.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    order = np.argsort(b, kind="stable")
    b, s, sh = b[order], s[order], np.minimum(sh[order], s[order])
    if np.any(np.diff(b) == 0):
        raise ValueError("bins must be unique")
    seg = np.floor_divide(b, k)
    segments, inv = np.unique(seg, return_inverse=True)
    n = np.bincount(inv).astype(np.float64)
    acc = np.bincount(inv, weights=s * s, minlength=segments.size)
    # dense along the bins, one row per segment (from the first segment's first bin), so that a lag is a
    # column offset within a row and pairs never cross a segment's edge; gaps hold 0 (no contribution)
    first = int(segments[0]) * k
    rows = int(segments[-1]) - int(segments[0]) + 1
    at = segments - segments[0]
    parts = [(np.sqrt(np.maximum(s * s - sh * sh, 0.0)), envelope_correlation,
              int(math.ceil(_MAX_LAG_RESOLUTIONS * float(resolution_m) / bl)))]
    if np.any(sh > 0):
        parts.append((sh, shared_correlation, int(math.ceil(shared_window_m(resolution_m, filter_order) / bl))))
    for values, correlation, reach in parts:
        dense = np.zeros(rows * k)
        dense[b - first] = values
        grid = dense.reshape(rows, k)
        max_lag = min(reach, k - 1)
        rho = correlation(np.arange(max_lag + 1) * bl, resolution_m, filter_order)
        cross = np.zeros(rows)
        for lag in range(1, max_lag + 1):
            if rho[lag] != 0.0:
                cross += rho[lag] * np.einsum("ij,ij->i", grid[:, :-lag], grid[:, lag:])
        acc += 2.0 * cross[at]
    return segments, np.sqrt(np.maximum(acc, 0.0)) / n
