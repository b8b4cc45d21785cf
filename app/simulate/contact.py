"""What the axle box feels of the running surfaces: roughness through the wheel–track dynamics.

A height ``r(t)`` of the rail or wheel surface under the contact (rail
roughness, a weld, a wheel flat; up positive, a dip is negative) drives the
wheel as the same linear wheel–track system that makes the sleeper-passage
amplitude (:mod:`app.analysis.stiffness.track_dynamics`): the unsprung mass on
a linearised Hertz spring on a Timoshenko rail on discrete supports,

    a(f) = H(f) r(f),      H = (1 / m) / (alpha_w + alpha_c + alpha_t)

(:func:`~app.analysis.stiffness.track_dynamics.wheel_rail_transfer`). The
system is time-invariant, so ``r`` is sampled at the wheel's position sample
by sample (the speed varies freely) and filtered in time by the FIR of
``H``. :class:`ContactFilter` builds that FIR for one superstructure type at
one sample rate: ``H`` on the FFT grid (computed on a coarser grid and
interpolated: it is smooth at the damping of :class:`~app.simulate.amplitude.ResonanceResponse`),
faded out between 2.5 and 3.5 kHz (above that the model's rail, 12 elements
per bay, is not credible; the roughness spectrum ends at 1.1 kHz at 55 m/s)
and between 0.4 and 0.5 ``fs`` (the recorder's anti-alias filter), cut where
the impulse response has decayed; its few milliseconds of non-causal ringing
(the band limit) are kept as a lookahead.

Units. The response is physical: m/s² per m of surface height, so the
depths of welds and flats can be read back from it. The simulator's
sleeper-passage amplitude is its own ``K_type`` at ``v_ref``
(:data:`app.simulate.track.SUPERSTRUCTURE_AMPLITUDE`), which is
:func:`type_scale` times the model's ``A(k_type, v_ref)`` (2.1 on slab, 1.25
on B91 without pads, 0.64 with pads): roughness weighs that much less (more)
against the sleeper passage than in the physics.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from scipy.signal import oaconvolve

from app.analysis.stiffness.track_dynamics import (
    TrackParameters,
    sleeper_passage_amplitude,
    wheel_rail_transfer,
)

__all__ = ["ContactFilter", "type_scale"]

#: The impulse response is cut where what is left of its energy falls below this fraction.
_TAIL = 1e-7
#: Longest impulse response considered, s.
_MAX_IR_S = 0.5
#: Non-causal part kept (the symmetric ringing of the band limit), s.
_LOOKAHEAD_S = 0.004
#: Above this the model (12 rail elements per bay) is not credible: ``H`` fades out to _F_STOP, Hz.
_F_FADE = 2500.0
_F_STOP = 3500.0


def _grid() -> np.ndarray:
    """Where ``H`` is computed: 1 Hz steps to 1.4 kHz (the pinned-pinned resonance is sharp), then 4 Hz."""
    return np.concatenate([np.arange(1.0, 1400.0, 1.0), np.arange(1400.0, _F_STOP + 4.0, 4.0)])


@lru_cache(maxsize=16)
def _transfer(params: TrackParameters) -> np.ndarray:
    """``H`` on :func:`_grid` (complex, m/s² per m)."""
    return wheel_rail_transfer(params, _grid())


@lru_cache(maxsize=32)
def _taps(params: TrackParameters, fs: float) -> tuple[np.ndarray, int]:
    """The FIR (lookahead taps first) and its lookahead in samples."""
    n = 1 << int(math.ceil(math.log2(fs * _MAX_IR_S)))
    f = np.fft.rfftfreq(n, 1.0 / fs)
    fc, hc = _grid(), _transfer(params)
    h = np.zeros(f.size, dtype=np.complex128)
    below = f < fc[0]  # under 1 Hz the wheel follows the rail: a = -omega² r
    h[below] = -((2 * np.pi * f[below]) ** 2)
    inside = ~below & (f <= fc[-1])
    h[inside] = np.interp(f[inside], fc, hc.real) + 1j * np.interp(f[inside], fc, hc.imag)
    stop = min(_F_STOP, 0.5 * fs)
    fade = min(_F_FADE, 0.4 * fs)
    h *= np.where(f <= fade, 1.0, 0.5 * (1.0 + np.cos(np.pi * np.clip((f - fade) / (stop - fade), 0.0, 1.0))))
    ir = np.fft.irfft(h, n)
    look = int(math.ceil(_LOOKAHEAD_S * fs))
    causal = ir[: n // 2]
    energy = np.cumsum(causal[::-1] ** 2)[::-1]
    keep = int(np.searchsorted(-energy, -_TAIL * energy[0])) + 1
    out = np.concatenate([ir[n - look :], causal[: max(keep, 16)]])
    out.setflags(write=False)
    return out, look


def type_scale(params: TrackParameters, amplitude_vref: float, v_ref_mps: float) -> float:
    """``K_type / A(k_type, v_ref)``: the simulator's sleeper amplitude per the model's, at ``v_ref``."""
    model = float(sleeper_passage_amplitude(params, np.array([v_ref_mps]))[0])
    return float(amplitude_vref) / model


class ContactFilter:
    """The FIR of ``scale * H(f)`` at sample rate ``fs`` (see the module docstring).

    Parameters
    ----------
    params : TrackParameters
        The wheel–track system (a superstructure type's).
    fs : float
        Sample rate, Hz.
    scale : float
        Factor on the response (:func:`type_scale`).
    """

    def __init__(self, params: TrackParameters, fs: float, scale: float = 1.0) -> None:
        if not (math.isfinite(fs) and fs > 0):
            raise ValueError(f"fs: must be > 0 Hz, got {fs!r}")
        if not (math.isfinite(scale) and scale >= 0):
            raise ValueError(f"scale: must be >= 0, got {scale!r}")
        self.fs = float(fs)
        taps, self.lookahead = _taps(params, self.fs)
        self.taps = taps * float(scale)
        #: samples of input before an output sample that the output depends on
        self.history = int(self.taps.size - 1 - self.lookahead)

    def apply(self, r: np.ndarray) -> np.ndarray:
        """Response to an input from :attr:`history` samples before the output to :attr:`lookahead` after it.

        Parameters
        ----------
        r : numpy.ndarray
            Surface height under the contact, m: ``history + n + lookahead`` samples.

        Returns
        -------
        numpy.ndarray
            The ``n`` output samples, m/s².
        """
        r = np.asarray(r, dtype=np.float64)
        if r.size <= self.history + self.lookahead:
            raise ValueError(f"r: needs more than {self.history + self.lookahead} samples, got {r.size}")
        return oaconvolve(r, self.taps, mode="valid")

