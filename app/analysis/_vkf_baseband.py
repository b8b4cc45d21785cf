"""Complex-baseband decimation of a segment before the VKF solve.

Railway orders live far below the ABA sample rate (the 11th wheel order is
≈ 210 Hz at 200 km/h, sampled at 10–50 kHz). The VKF only looks at a few Hz
around each order, so the segment is mixed down by the centre ``f_c`` of the
tracked band, low-pass filtered by a linear-phase Kaiser FIR (100 dB stop
band, 1e-5 pass-band ripple) and decimated by ``D``. The orders are solved on
that grid with their phases ``phi_n − 2π f_c k / fs`` — the same envelopes as
at the input rate, since mixing only moves the carrier — and the envelopes
are interpolated back to any input sample with a cubic spline (they are
smooth at the decimated rate: bandwidths ≪ fs/D).

Besides speed (D = 20–2000) this keeps the normal equations well conditioned:
r² scales with (fs/B)^(2q), and fs/B drops by D.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import firwin, kaiserord, upfirdn

__all__ = ["BasebandPlan", "plan_baseband", "to_baseband", "EnvelopeSpline"]

#: stop-band attenuation of the anti-alias filter, dB (pass-band ripple 1e-5)
_ATTEN_DB = 100.0
#: complex output rate relative to the one-sided pass band half-width W
_RATE_OVER_W = 2.5
#: guard band around the tracked orders, in multiples of the widest bandwidth
_GUARD_BW = 5.0
#: the pass band is never narrower than this many bandwidths (limits FIR length)
_MIN_W_BW = 10.0
#: automatic decimation only below this rate ratio is not worth it
_MIN_AUTO_FACTOR = 4


@dataclass(frozen=True)
class BasebandPlan:
    """How one segment is brought to complex baseband.

    Attributes
    ----------
    factor : int
        Decimation factor D.
    center : float
        Mixing frequency f_c, Hz.
    half_width : float
        One-sided pass band W around f_c that is kept flat, Hz.
    taps : ndarray
        Odd-length, symmetric low-pass FIR at the input rate.
    """

    factor: int
    center: float
    half_width: float
    taps: np.ndarray

    @property
    def delay(self) -> int:
        """Half length of the FIR, input samples (edge transient length)."""
        return (len(self.taps) - 1) // 2


def plan_baseband(
    f_lo: float, f_hi: float, bw_max: float, fs: float, decimation: str | int
) -> BasebandPlan | None:
    """Choose the decimation of a segment, or None for a full-rate solve.

    Parameters
    ----------
    f_lo, f_hi : float
        Lowest and highest tracked frequency in the segment, Hz.
    bw_max : float
        Widest bandwidth in the segment, Hz.
    fs : float
        Input sample rate, Hz.
    decimation : {"auto", "off"} or int
        Mode or a fixed factor.

    Raises
    ------
    ValueError
        If a fixed factor would alias the tracked band.
    """
    if decimation == "off" or decimation == 1:
        return None
    half_width = max((f_hi - f_lo) / 2.0 + _GUARD_BW * bw_max, _MIN_W_BW * bw_max)
    max_factor = int(np.floor(fs / (_RATE_OVER_W * half_width)))
    if decimation == "auto":
        if max_factor < _MIN_AUTO_FACTOR:
            return None
        factor = max_factor
    else:
        factor = int(decimation)
        if factor > max_factor:
            raise ValueError(
                f"decimation={factor} is too large: the tracked band "
                f"{f_lo:.3g}–{f_hi:.3g} Hz with bandwidth {bw_max:.3g} Hz needs a "
                f"decimation factor of at most {max(max_factor, 1)} at fs={fs:g} Hz"
            )
    rate = fs / factor
    width = (rate - 2.0 * half_width) / (fs / 2.0)
    numtaps, beta = kaiserord(_ATTEN_DB, width)
    numtaps |= 1  # odd length: integer group delay
    taps = firwin(numtaps, rate / 2.0, window=("kaiser", beta), fs=fs)
    return BasebandPlan(factor=factor, center=(f_lo + f_hi) / 2.0, half_width=half_width, taps=taps)


def mixing_phase(plan: BasebandPlan, index: np.ndarray, fs: float) -> np.ndarray:
    """Phase of the mixing oscillator at global sample indices, rad (mod 2π)."""
    cycles = np.mod(plan.center / fs * np.asarray(index, dtype=np.float64), 1.0)
    return 2.0 * np.pi * cycles


def to_baseband(y: np.ndarray, first_index: int, plan: BasebandPlan, fs: float) -> np.ndarray:
    """Mix, filter and decimate a segment.

    Parameters
    ----------
    y : ndarray, shape (channels, n)
        Segment of the input, global sample indices ``first_index …``.
    first_index : int
        Global index of ``y[:, 0]``.
    plan : BasebandPlan
    fs : float
        Input sample rate, Hz.

    Returns
    -------
    ndarray, complex, shape (channels, M)
        Baseband samples at global indices ``first_index + m*D``,
        ``M = ceil(n / D)``; samples outside the segment count as zero.
    """
    n = y.shape[-1]
    d = plan.factor
    m = -(-n // d)
    c = plan.delay
    pad = (-c) % d
    skip = (c + pad) // d
    osc = np.exp(-1j * mixing_phase(plan, np.arange(first_index, first_index + n), fs))
    out = np.empty((y.shape[0], m), dtype=np.complex128)
    for ch in range(y.shape[0]):
        mixed = np.concatenate([np.zeros(pad, dtype=np.complex128), y[ch] * osc])
        filtered = upfirdn(plan.taps, mixed, up=1, down=d)
        out[ch] = filtered[skip : skip + m]
    return out


class EnvelopeSpline:
    """Cubic-spline interpolation of decimated envelopes to input samples.

    Parameters
    ----------
    envelope : ndarray, complex, shape (channels, s, M)
        Envelopes on the grid ``first_index + m*factor``.
    first_index : int
        Global index of grid point 0.
    factor : int
        Grid spacing, input samples.
    """

    def __init__(self, envelope: np.ndarray, first_index: int, factor: int) -> None:
        self.first_index = int(first_index)
        self.factor = int(factor)
        self.grid_size = envelope.shape[-1]
        if factor == 1:
            self._values = envelope
            self._spline = None
        else:
            grid = np.arange(self.grid_size, dtype=np.float64)
            self._values = None
            self._spline = CubicSpline(grid, envelope, axis=-1, bc_type="not-a-knot")

    def __call__(self, index: np.ndarray) -> np.ndarray:
        """Envelopes at global sample indices (channels, s, len(index))."""
        index = np.asarray(index)
        if self._spline is None:
            return self._values[..., index - self.first_index]
        x = (index - self.first_index) / self.factor
        return self._spline(x)
