"""Residual of a signal after removing railway orders, at the full sample rate.

The pipeline stores the RMS of ``y − Σ waveforms`` per 25 cm bin. The order
envelopes are known on a coarse output grid (every few cm of travel); the
waveforms are needed at every sample. This module evaluates them in one
compiled pass (numba), without full-rate temporaries per order.

The orders must be *railway orders*: track orders with the phases ``h·m0·ψ``
(the sleeper passage ``h = 1`` and its harmonics ``h = 2, 3``) and wheel
orders with the phases ``l·m1·ψ`` (``l = 1 … L``, any subset), so that each
group's sum is a polynomial in one phasor, ``exp(i·m0·ψ)`` or
``exp(i·m1·ψ)`` (Horner's scheme).

With ``demodulate=True`` the same pass also returns the residual mixed down by
the sleeper-passage phase, ``r·exp(−i·m0·ψ)``, averaged over every grid
interval: the residual's content around ``f_s`` at the grid rate, from which
:mod:`app.analysis.roughness` measures the broadband floor beside the sleeper
order (a few operations per sample, no second pass).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["railway_residual"]


@numba.njit(cache=True, nogil=True)
def _residual_kernel(
    y: np.ndarray,
    psi: np.ndarray,
    track: np.ndarray,
    track_slope: np.ndarray,
    wheel: np.ndarray,
    wheel_slope: np.ndarray,
    step: int,
    m0: float,
    m1: float,
    out: np.ndarray,
    demod: np.ndarray,
    want_demod: bool,
) -> None:  # pragma: no cover - compiled; covered through railway_residual
    n = y.shape[0]
    h_max = track.shape[1] - 1
    l_max = wheel.shape[1] - 1
    for k in range(n):
        j = k // step
        f = float(k - j * step)
        th = psi[k]
        e1 = complex(np.cos(m1 * th), np.sin(m1 * th))
        acc = wheel[j, l_max] + f * wheel_slope[j, l_max]
        for order in range(l_max - 1, 0, -1):
            acc = acc * e1 + (wheel[j, order] + f * wheel_slope[j, order])
        e0 = complex(np.cos(m0 * th), np.sin(m0 * th))
        tr = track[j, h_max] + f * track_slope[j, h_max]
        for order in range(h_max - 1, 0, -1):
            tr = tr * e0 + (track[j, order] + f * track_slope[j, order])
        out[k] = y[k] - (acc * e1 + tr * e0).real
        if want_demod:
            demod[j] += out[k] * e0.conjugate()


def _dense(env: np.ndarray, powers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grid values ``(M, max power + 1)`` by power (zero where absent) and their slopes per sample."""
    dense = np.zeros((env.shape[1] + 1, int(powers.max()) + 1), dtype=np.complex128)
    dense[:-1, powers] = env.T
    dense[-1, powers] = env[:, -1]  # the last grid value held
    return np.ascontiguousarray(dense[:-1]), np.ascontiguousarray(np.diff(dense, axis=0))


def railway_residual(
    y: np.ndarray,
    psi: np.ndarray,
    envelope: np.ndarray,
    step: int,
    multipliers: np.ndarray,
    powers: np.ndarray | None = None,
    n_track: int = 1,
    demodulate: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """``y − Σ_n Re(a_n·exp(i·φ_n))`` with envelopes linear between grid points.

    Parameters
    ----------
    y : ndarray, shape (N,)
        Signal, e.g. an axle-box acceleration in m/s².
    psi : ndarray, shape (N,)
        Phase per unit multiplier, rad: order ``n`` has the phase
        ``multipliers[n] · psi``.
    envelope : ndarray, complex, shape (s, M)
        Peak phasors ``a_n`` of the orders at the grid samples ``0, step,
        2·step, …`` of ``y`` (``M ≥ ceil(N / step)``). Between grid points they
        are interpolated linearly; after the last one they are held.
    step : int
        Grid spacing, samples (≥ 1).
    multipliers : ndarray, shape (s,)
        Railway order multipliers, Hz per (m/s) or any unit that matches
        ``psi``: the ``n_track`` track orders ``powers[n]·m0`` first, then the
        wheel orders ``powers[n]·m1``.
    powers : ndarray of int, shape (s,), optional
        Harmonic number of every order within its group (≥ 1). Default: one
        track order and wheel orders 1, 2, … (``[m0, m1, 2·m1, …]``).
    n_track : int
        Number of track orders (the first rows), ≥ 1.
    demodulate : bool, optional
        Also return the residual mixed down by the first track order's phase
        ``m0·ψ`` (the sleeper passage) and averaged over each grid interval.

    Returns
    -------
    ndarray, shape (N,)
        Residual, in the unit of ``y``.
    ndarray, complex, shape (ceil(N / step),)
        Only with ``demodulate``: ``mean(r[k]·exp(−i·m0·ψ[k]))`` over the samples
        ``k`` of grid interval ``j`` (``j·step ≤ k < (j + 1)·step``), in the unit of
        ``y``. A component ``A·cos(m0·ψ + 2π·δf·t + φ)`` of the residual appears in it
        as ``(A/2)·exp(i(2π·δf·t + φ))`` (times the interval's sinc droop,
        ``sinc(δf·step/fs)``), its image at ``−(2·f_s + δf)``.

    Raises
    ------
    ValueError
        On shape mismatches, ``step < 1``, a grid too short for ``y``, or
        multipliers that are not railway orders.
    """
    y = np.ascontiguousarray(y, dtype=np.float64)
    psi = np.ascontiguousarray(psi, dtype=np.float64)
    env = np.asarray(envelope, dtype=np.complex128)
    mult = np.asarray(multipliers, dtype=np.float64)
    if y.ndim != 1 or psi.shape != y.shape:
        raise ValueError(f"y and psi must be 1-D of equal length, got {y.shape} and {psi.shape}")
    if env.ndim != 2 or env.shape[0] != mult.size or mult.size < 2:
        raise ValueError(
            f"envelope must have shape (s, M) with s = len(multipliers) >= 2, got {env.shape} "
            f"and {mult.size} multipliers"
        )
    if int(step) != step or step < 1:
        raise ValueError(f"step must be a positive integer, got {step!r}")
    step = int(step)
    if env.shape[1] < -(-y.size // step):
        raise ValueError(f"envelope grid of {env.shape[1]} points does not cover {y.size} samples at step {step}")
    if powers is None:
        powers = np.concatenate([[1], np.arange(1, mult.size)])
    powers = np.asarray(powers)
    if powers.shape != mult.shape or not 1 <= int(n_track) < mult.size or np.any(powers < 1):
        raise ValueError(f"powers must hold one integer >= 1 per multiplier and 1 <= n_track < {mult.size}")
    n_track = int(n_track)
    m0, m1 = mult[0] / powers[0], mult[n_track] / powers[n_track]
    base = np.where(np.arange(mult.size) < n_track, m0, m1)
    if not np.allclose(mult, powers * base, rtol=1e-12, atol=0.0) or len(set(powers[:n_track])) < n_track \
            or len(set(powers[n_track:])) < mult.size - n_track:
        raise ValueError("multipliers must be [h·m0 …, l·m1 …] (railway orders)")
    track, track_slope = _dense(env[:n_track], powers[:n_track])
    wheel, wheel_slope = _dense(env[n_track:], powers[n_track:])
    track_slope /= step
    wheel_slope /= step
    out = np.empty_like(y)
    n_grid = -(-y.size // step)
    demod = np.zeros(n_grid if demodulate else 1, dtype=np.complex128)
    if y.size:
        _residual_kernel(y, psi, track, track_slope, wheel, wheel_slope, step, float(m0), float(m1), out,
                         demod, bool(demodulate))
    if not demodulate:
        return out
    counts = np.full(n_grid, float(step))
    if n_grid:
        counts[-1] = y.size - (n_grid - 1) * step
    return out, demod / counts
