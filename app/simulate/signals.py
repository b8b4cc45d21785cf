"""Synthetic test signals with known ground truth.

Every component of a :class:`SyntheticSignal` is, sample for sample,
``amplitude * cos(phi + phase)`` with ``phi = 2*pi*cumsum(freqs)/fs`` -- the
phase convention of the VKF engine (paper Eq. 3; the first sample already
includes ``freqs[0]/fs``). Tests and benchmarks can therefore compare
envelopes (``amplitude * exp(1j*phase)``), not only waveforms.

Two generators are provided:

* :func:`paper_signal` -- the validation signal of the method paper
  (Eqs. 21-23), with the physically correct phase ``2*pi*integral(f dt)``.
* :func:`railway_signal` -- an axle-box-acceleration-like signal: the
  sleeper-passage order plus the wheel out-of-roundness orders of a train
  running at a variable speed, with broadband noise.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from app.analysis.units import KMH_PER_MPS

__all__ = [
    "SyntheticSignal",
    "paper_signal",
    "phase_from_freqs",
    "railway_signal",
    "DEFAULT_OOR_RADIUS_UM",
]

#: Default radius deviation (µm) of wheel orders 1..11 used by :func:`railway_signal`.
DEFAULT_OOR_RADIUS_UM: tuple[float, ...] = (
    20.0,
    12.0,
    8.0,
    6.0,
    10.0,
    4.0,
    3.0,
    8.0,
    2.0,
    1.5,
    1.0,
)

SpeedSpec = tuple[float, float] | Sequence[float] | np.ndarray | Callable[[np.ndarray], ArrayLike]
AmplitudeSpec = float | np.ndarray | Callable[[np.ndarray, np.ndarray], ArrayLike] | None


@dataclass(frozen=True, eq=False)
class SyntheticSignal:
    """A synthetic signal and its noise-free components.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times, s (``k / fs``, k = 0..N-1).
    y : ndarray, shape (N,)
        Observed signal: ``waveforms.sum(axis=0)`` plus white Gaussian noise
        (m/s² for acceleration signals).
    fs : float
        Sample rate, Hz.
    freqs : ndarray, shape (s, N)
        Instantaneous frequency of each component, Hz.
    phi : ndarray, shape (s, N)
        Carrier phase ``2*pi*cumsum(freqs, axis=-1)/fs``, rad.
    amplitude : ndarray, shape (s, N)
        True peak amplitude of each component (same unit as ``y``).
    phase : ndarray, shape (s, N)
        True phase offset of each component relative to ``phi``, rad.
    waveforms : ndarray, shape (s, N)
        Noise-free components, exactly ``amplitude * cos(phi + phase)``.
    speed : ndarray, shape (N,) or None
        Train speed, m/s (None for signals without a speed).
    noise_std : float
        Standard deviation of the added noise.
    names : tuple of str
        One label per component.
    position : ndarray, shape (N,) or None
        Distance travelled, m (``cumsum(speed)/fs``), or None.
    """

    t: np.ndarray
    y: np.ndarray
    fs: float
    freqs: np.ndarray
    phi: np.ndarray
    amplitude: np.ndarray
    phase: np.ndarray
    waveforms: np.ndarray
    speed: np.ndarray | None
    noise_std: float
    names: tuple[str, ...] = ()
    position: np.ndarray | None = None

    @property
    def envelope(self) -> np.ndarray:
        """Complex envelope ``amplitude * exp(1j*phase)``, shape (s, N).

        This is what the VKF engine's ``VKFResult.envelope`` estimates.
        """
        return self.amplitude * np.exp(1j * self.phase)

    @property
    def clean(self) -> np.ndarray:
        """Noise-free signal ``waveforms.sum(axis=0)``, shape (N,)."""
        return self.waveforms.sum(axis=0)

    @property
    def noise(self) -> np.ndarray:
        """The added noise ``y - clean``, shape (N,)."""
        return self.y - self.clean

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(self.y.shape[-1])


def phase_from_freqs(freqs: ArrayLike, fs: float, phase0: ArrayLike | None = None) -> np.ndarray:
    """Carrier phase of instantaneous frequencies (VKF convention).

    Parameters
    ----------
    freqs : array_like, shape (..., N)
        Instantaneous frequencies, Hz.
    fs : float
        Sample rate, Hz.
    phase0 : array_like, shape (...), optional
        Initial phase added to each row, rad.

    Returns
    -------
    ndarray, shape (..., N)
        ``phase0 + 2*pi*cumsum(freqs, axis=-1)/fs``, rad.
    """
    f = np.asarray(freqs, dtype=float)
    phi = 2.0 * np.pi * np.cumsum(f, axis=-1) / float(fs)
    if phase0 is not None:
        phi = phi + np.asarray(phase0, dtype=float)[..., None]
    return phi


def _check_common(duration: float, fs: float, noise_std: float) -> int:
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"fs must be a positive finite sample rate in Hz, got {fs!r}")
    if not np.isfinite(duration) or duration <= 0:
        raise ValueError(f"duration must be a positive finite time in s, got {duration!r}")
    if not np.isfinite(noise_std) or noise_std < 0:
        raise ValueError(f"noise_std must be finite and >= 0, got {noise_std!r}")
    n = int(round(duration * fs))
    if n < 2:
        raise ValueError(f"duration * fs must give at least 2 samples, got {n}")
    return n


def _check_nyquist(freqs: np.ndarray, fs: float) -> None:
    fmax = float(np.max(freqs))
    if fmax >= fs / 2:
        raise ValueError(
            f"fs = {fs} Hz is too low: the highest component frequency is {fmax:.1f} Hz "
            f"(must stay below fs/2)"
        )


def _assemble(
    t: np.ndarray,
    fs: float,
    freqs: np.ndarray,
    amplitude: np.ndarray,
    phase: np.ndarray,
    noise: np.ndarray,
    noise_std: float,
    *,
    speed: np.ndarray | None = None,
    position: np.ndarray | None = None,
    names: tuple[str, ...] = (),
) -> SyntheticSignal:
    phi = phase_from_freqs(freqs, fs)
    waveforms = amplitude * np.cos(phi + phase)
    y = waveforms.sum(axis=0) + noise
    return SyntheticSignal(
        t=t,
        y=y,
        fs=float(fs),
        freqs=freqs,
        phi=phi,
        amplitude=amplitude,
        phase=phase,
        waveforms=waveforms,
        speed=speed,
        noise_std=float(noise_std),
        names=names,
        position=position,
    )


def paper_signal(
    duration: float = 60.0,
    fs: float = 12000.0,
    noise_std: float = 0.75,
    seed: int | None = 0,
) -> SyntheticSignal:
    """The validation signal of the method paper (Eqs. 21-23).

    Three components ``X_n = a_n(t) cos(phi_n(t) + p_n(t))`` with

    * a = [0.02 t + 1,  1 + 0.5 sin(2 pi 0.02 t) cos(2 pi 0.04 t),  1]
    * f = [600 + 120 cos(2 pi 0.03 t),  240 - 120 cos(2 pi 0.01 t),  500] Hz
    * p = [0.06 t - 2,  0,  -1] rad

    plus white Gaussian noise. Unlike the printed ``cos(2 pi f t + p)``, the
    carrier phase is the integral of the frequency, ``phi_n = 2 pi
    cumsum(f_n)/fs`` (the VKF convention), so ``f_n`` really is the
    instantaneous frequency. Components 1 and 3 cross (f_1 dips to 480 Hz).

    Parameters
    ----------
    duration : float
        Signal length, s (the paper: 60 s).
    fs : float
        Sample rate, Hz (the paper: 12 kHz); must exceed 1440 Hz.
    noise_std : float
        Standard deviation of the additive noise, m/s² (the paper: 0.75).
    seed : int or None
        Seed of the noise generator.

    Returns
    -------
    SyntheticSignal
        With ``speed = None`` and names ``("X1", "X2", "X3")``.
    """
    n = _check_common(duration, fs, noise_std)
    t = np.arange(n) / float(fs)
    amplitude = np.vstack(
        [
            0.02 * t + 1.0,
            1.0 + 0.5 * np.sin(2 * np.pi * 0.02 * t) * np.cos(2 * np.pi * 0.04 * t),
            np.ones_like(t),
        ]
    )
    freqs = np.vstack(
        [
            600.0 + 120.0 * np.cos(2 * np.pi * 0.03 * t),
            240.0 - 120.0 * np.cos(2 * np.pi * 0.01 * t),
            np.full_like(t, 500.0),
        ]
    )
    _check_nyquist(freqs, fs)
    phase = np.vstack([0.06 * t - 2.0, np.zeros_like(t), np.full_like(t, -1.0)])
    rng = np.random.default_rng(seed)
    noise = noise_std * rng.standard_normal(n)
    return _assemble(t, fs, freqs, amplitude, phase, noise, noise_std, names=("X1", "X2", "X3"))


def _speed_profile(speed_kmh: SpeedSpec, t: np.ndarray, duration: float) -> np.ndarray:
    """Speed in m/s at the sample times."""
    n = t.size
    if callable(speed_kmh):
        v = np.asarray(speed_kmh(t), dtype=float)
        if v.ndim == 0:
            v = np.full(n, float(v))
    else:
        v = np.asarray(speed_kmh, dtype=float)
        if v.shape == (2,):
            v_lo, v_hi = float(v[0]), float(v[1])
            # raised cosine: v_lo -> v_hi at mid-signal -> v_lo
            v = v_lo + (v_hi - v_lo) * 0.5 * (1.0 - np.cos(2.0 * np.pi * t / duration))
        elif v.ndim == 0:
            v = np.full(n, float(v))
    if v.shape != (n,):
        raise ValueError(
            f"speed_kmh must be a (v_min, v_max) pair, a scalar, an array of shape ({n},) "
            f"or a callable of t returning one; got shape {v.shape}"
        )
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError("speed_kmh must be finite and >= 0 everywhere")
    return v / KMH_PER_MPS


def _default_sleeper_amplitude(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """1.5 m/s² with a ±30 % variation of 120 m wavelength along the track."""
    return 1.5 * (1.0 + 0.3 * np.sin(2.0 * np.pi * x / 120.0))


def railway_signal(
    duration: float = 60.0,
    fs: float = 10000.0,
    *,
    speed_kmh: SpeedSpec = (40.0, 200.0),
    wheel_diameter: float = 0.92,
    sleeper_spacing: float = 0.6,
    sleeper_amplitude: AmplitudeSpec = None,
    sleeper_phase: float = 0.0,
    oor_radius_um: ArrayLike | None = None,
    oor_phase: ArrayLike | None = None,
    noise_std: float = 1.0,
    seed: int | None = 0,
) -> SyntheticSignal:
    """An axle-box-acceleration-like signal with known order content.

    Components (in the product's order stack): index 0 is the sleeper
    passage, ``f_s = v / sleeper_spacing``; indices 1..n are the wheel
    orders ``f_l = l v / (pi d_w)``, l = 1..n.

    * Sleeper passage: amplitude ``sleeper_amplitude(t, x)`` (m/s²), phase
      ``sleeper_phase``; its carrier ``phi_s = 2 pi x / d_s`` is locked to the
      distance travelled x.
    * Wheel order l: a radius deviation ``rho_l cos(l theta + psi_l)``
      (``theta = 2 x / d_w`` the wheel angle) gives an axle-box acceleration
      ``rho_l omega_l^2 cos(l theta + psi_l + pi)`` with ``omega_l = 2 l v / d_w``
      (quasi-stationary: the ``rho_l l dω/dt`` term is neglected). So
      ``amplitude[l] = rho_l omega_l^2`` (m/s²) and ``phase[l] = psi_l + pi``
      wrapped to (-pi, pi].

    Parameters
    ----------
    duration : float
        Signal length, s.
    fs : float
        Sample rate, Hz.
    speed_kmh : (float, float), float, array_like of shape (N,) or callable
        Train speed in km/h. A pair ``(v_min, v_max)`` (default (40, 200))
        gives a raised-cosine profile v_min -> v_max (at mid-signal) -> v_min;
        a callable is called with the sample times t (s).
    wheel_diameter : float
        Wheel diameter d_w, m.
    sleeper_spacing : float
        Sleeper spacing d_s, m.
    sleeper_amplitude : float, array_like of shape (N,) or callable, optional
        Peak acceleration amplitude of the sleeper-passage order, m/s². A
        callable is called as ``f(t, x)`` with sample times t (s) and distance
        travelled x (m). Default: ``1.5 (1 + 0.3 sin(2 pi x / 120 m))``.
    sleeper_phase : float
        Phase of the sleeper-passage component relative to its carrier, rad.
    oor_radius_um : array_like of shape (n,), optional
        Radius deviation rho_l of wheel orders 1..n, µm (>= 0). Default
        :data:`DEFAULT_OOR_RADIUS_UM` (11 orders).
    oor_phase : array_like of shape (n,), optional
        Phase psi_l of each radius deviation, rad. Default: uniform random
        from ``seed``.
    noise_std : float
        Standard deviation of the white Gaussian noise, m/s².
    seed : int or None
        Seed of the random generator (OOR phases, then noise).

    Returns
    -------
    SyntheticSignal
        With ``speed`` (m/s), ``position`` (m) and names
        ``("sleeper", "wheel 1", ..., "wheel n")``.
    """
    n = _check_common(duration, fs, noise_std)
    if not np.isfinite(wheel_diameter) or wheel_diameter <= 0:
        raise ValueError(f"wheel_diameter must be positive (m), got {wheel_diameter!r}")
    if not np.isfinite(sleeper_spacing) or sleeper_spacing <= 0:
        raise ValueError(f"sleeper_spacing must be positive (m), got {sleeper_spacing!r}")
    rho_um = np.asarray(DEFAULT_OOR_RADIUS_UM if oor_radius_um is None else oor_radius_um, float)
    if (
        rho_um.ndim != 1
        or rho_um.size == 0
        or not np.all(np.isfinite(rho_um))
        or np.any(rho_um < 0)
    ):
        raise ValueError("oor_radius_um must be a non-empty 1-D array of finite values >= 0 (µm)")
    n_orders = rho_um.size
    rng = np.random.default_rng(seed)
    if oor_phase is None:
        psi = rng.uniform(-np.pi, np.pi, n_orders)
    else:
        psi = np.asarray(oor_phase, dtype=float)
        if psi.shape != (n_orders,) or not np.all(np.isfinite(psi)):
            raise ValueError(f"oor_phase must be a finite array of shape ({n_orders},)")

    t = np.arange(n) / float(fs)
    v = _speed_profile(speed_kmh, t, duration)
    x = np.cumsum(v) / float(fs)

    if sleeper_amplitude is None:
        a_s = _default_sleeper_amplitude(t, x)
    elif callable(sleeper_amplitude):
        a_s = np.asarray(sleeper_amplitude(t, x), dtype=float)
    else:
        a_s = np.asarray(sleeper_amplitude, dtype=float)
    a_s = np.broadcast_to(a_s, (n,)).astype(float) if a_s.ndim == 0 else a_s
    if a_s.shape != (n,) or not np.all(np.isfinite(a_s)) or np.any(a_s < 0):
        raise ValueError(f"sleeper_amplitude must give finite values >= 0 of shape ({n},)")

    orders = np.arange(1, n_orders + 1, dtype=float)[:, None]
    f_wheel = orders * v[None, :] / (np.pi * wheel_diameter)
    f_sleeper = v / sleeper_spacing
    freqs = np.vstack([f_sleeper[None, :], f_wheel])
    _check_nyquist(freqs, fs)

    omega = 2.0 * orders * v[None, :] / wheel_diameter  # rad/s of order l
    amp_wheel = (rho_um[:, None] * 1e-6) * omega**2
    phase_wheel = np.angle(np.exp(1j * (psi + np.pi)))
    amplitude = np.vstack([a_s[None, :], amp_wheel])
    phase = np.vstack(
        [np.full((1, n), float(sleeper_phase)), np.repeat(phase_wheel[:, None], n, axis=1)]
    )
    noise = noise_std * rng.standard_normal(n)
    names = ("sleeper",) + tuple(f"wheel {int(k)}" for k in orders[:, 0])
    return _assemble(
        t, fs, freqs, amplitude, phase, noise, noise_std, speed=v, position=x, names=names
    )
