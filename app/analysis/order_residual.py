"""Residual of a signal after removing railway orders, at the full sample rate.

The pipeline stores the RMS of ``y − Σ waveforms`` per 25 cm bin. The order
envelopes are known on a coarse output grid (every few cm of travel); the
waveforms are needed at every sample. This module evaluates them in one
compiled pass (numba), without full-rate temporaries per order.

The orders must be *railway orders*: order 0 has the phase ``m0·ψ`` (the
sleeper passage) and orders ``l = 1 … L`` the phases ``l·m1·ψ`` (wheel
orders), so that the wheel-order sum is a polynomial in one phasor
``exp(i·m1·ψ)`` (Horner's scheme).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["railway_residual"]


@numba.njit(cache=True, nogil=True)
def _residual_kernel(
    y: np.ndarray,
    psi: np.ndarray,
    env: np.ndarray,
    slope: np.ndarray,
    step: int,
    m0: float,
    m1: float,
    out: np.ndarray,
) -> None:  # pragma: no cover - compiled; covered through railway_residual
    n = y.shape[0]
    s = env.shape[1]
    for k in range(n):
        j = k // step
        f = float(k - j * step)
        th = psi[k]
        e1 = complex(np.cos(m1 * th), np.sin(m1 * th))
        acc = env[j, s - 1] + f * slope[j, s - 1]
        for order in range(s - 2, 0, -1):
            acc = acc * e1 + (env[j, order] + f * slope[j, order])
        es = complex(np.cos(m0 * th), np.sin(m0 * th))
        sleeper = (env[j, 0] + f * slope[j, 0]) * es
        out[k] = y[k] - (acc * e1 + sleeper).real


def railway_residual(
    y: np.ndarray,
    psi: np.ndarray,
    envelope: np.ndarray,
    step: int,
    multipliers: np.ndarray,
) -> np.ndarray:
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
        Railway order multipliers: ``[m0, m1, 2·m1, …, (s−1)·m1]`` (sleeper
        order first, then the wheel orders), Hz per (m/s) or any unit that
        matches ``psi``.

    Returns
    -------
    ndarray, shape (N,)
        Residual, in the unit of ``y``.

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
    wheel = mult[1:]
    if not np.allclose(wheel, mult[1] * np.arange(1, wheel.size + 1), rtol=1e-12, atol=0.0):
        raise ValueError("multipliers must be [m0, m1, 2·m1, …] (railway orders)")
    # grid values transposed (M + 1, s) for locality, the last one held
    grid = np.concatenate([env, env[:, -1:]], axis=1).T
    slope = np.ascontiguousarray(np.diff(grid, axis=0) / step)
    grid = np.ascontiguousarray(grid[:-1])
    out = np.empty_like(y)
    if y.size:
        _residual_kernel(y, psi, grid, slope, step, float(mult[0]), float(mult[1]), out)
    return out
