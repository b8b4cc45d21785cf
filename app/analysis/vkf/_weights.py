"""Bandwidth ↔ weight mapping of the VKF and the length of its impulse response.

For a stationary order tracked over a long record, the VKF envelope is the
demodulated signal passed through the zero-phase low-pass

    H(ω) = 1 / (1 + r² · (2 sin(ω/2))^(2q)),      ω = 2π Δf / fs,

where Δf is the offset from the tracked frequency (the difference operator
∇^q has |1 − e^{−jω}|^(2q) = (2 sin(ω/2))^(2q)). The requested *full* −3 dB
(half-power) bandwidth B puts |H| = 1/√2 at Δf = ±B/2, hence

    r² = (√2 − 1) / (2 sin(π B / (2 fs)))^(2q).
"""

from __future__ import annotations

import numpy as np

__all__ = ["weight_squared", "decay_per_sample", "impulse_length"]

_HALF_POWER = np.sqrt(2.0) - 1.0


def weight_squared(bandwidth: np.ndarray | float, fs: float, q: int) -> np.ndarray:
    """Squared structural weight r² for a full −3 dB bandwidth.

    Parameters
    ----------
    bandwidth : array_like
        Full −3 dB bandwidth, Hz (> 0, < fs).
    fs : float
        Sample rate of the solve, Hz.
    q : int
        Difference order.

    Returns
    -------
    ndarray
        r², dimensionless.
    """
    x = 2.0 * np.sin(np.pi * np.asarray(bandwidth, dtype=np.float64) / (2.0 * fs))
    return _HALF_POWER / x ** (2 * q)


def bandwidth_from_weight(r2: np.ndarray | float, fs: float, q: int) -> np.ndarray:
    """Inverse of :func:`weight_squared`: full −3 dB bandwidth in Hz for r²."""
    x = (_HALF_POWER / np.asarray(r2, dtype=np.float64)) ** (1.0 / (2 * q))
    return 2.0 * fs * np.arcsin(np.minimum(x / 2.0, 1.0)) / np.pi


def decay_per_sample(r2: float, q: int) -> float:
    """Magnitude of the slowest-decaying pole of the stationary smoother.

    The poles solve 1 + r² (2 − z − 1/z)^q = 0; with u a q-th root of −1/r²,
    z + 1/z = 2 − u. The impulse response decays like ``rho**|k|`` with rho
    the largest pole magnitude inside the unit circle.
    """
    m = np.arange(q)
    u = r2 ** (-1.0 / q) * np.exp(1j * np.pi * (2 * m + 1) / q)
    b = 2.0 - u
    disc = np.sqrt(b * b - 4.0 + 0j)
    z = np.concatenate([(b + disc) / 2.0, (b - disc) / 2.0])
    mags = np.abs(z)
    inside = mags[mags < 1.0]
    return float(inside.max()) if inside.size else 0.0


def impulse_length(bandwidth: float, fs: float, q: int, tol: float = 1e-8) -> int:
    """Samples after which the smoother's impulse response fell below ``tol``.

    Parameters
    ----------
    bandwidth : float
        Full −3 dB bandwidth, Hz (the narrowest one of the segment).
    fs : float
        Sample rate of the solve, Hz.
    q : int
        Difference order.
    tol : float
        Relative level of the tail that is neglected.

    Returns
    -------
    int
        Number of samples, including a margin for the polynomial factor of
        the (near-)repeated poles.
    """
    rho = decay_per_sample(float(weight_squared(bandwidth, fs, q)), q)
    if rho <= 0.0:
        return q + 1
    n = np.log(tol) / np.log(rho)
    return int(np.ceil(1.25 * n)) + 4 * q
