"""Sleeper-passage amplitude of a wheel on a discretely supported rail, A(k, v).

The model (written for trackvkf; checked against an independent finite-element
vehicle–track model in ``docs/speed-conditioning.md``):

* **Track.** A Timoshenko rail (bending stiffness ``EI``, shear stiffness
  ``kappa G A``, mass per metre) on point supports every ``d_s`` m; each
  support is a rail pad (spring + dashpot), half a sleeper (a mass) and the
  ballast under it (spring + dashpot, stiffness ``k`` per rail seat — the
  "support stiffness" the indicator is about). The rail is a finite beam of
  ``n_bays`` bays (free ends far from the load) discretised with two-node
  Timoshenko elements; the sleeper degrees of freedom are condensed into a
  frequency-dependent support stiffness. :func:`point_receptance` solves the
  harmonic problem for a unit force at positions within the central bay.
* **Wheel.** The unsprung mass ``m`` on a linearised Hertz contact spring
  ``k_H = 3 P^(1/3) / (2 G)`` (static wheel load ``P``); the primary
  suspension decouples the rest of the vehicle above a few Hz. A roughness
  ``r`` at the contact drives the wheel acceleration
  ``|a / r| = (1 / m) / |alpha_w + alpha_c + alpha_t|`` with
  ``alpha_w = -1 / (m omega^2)``, ``alpha_c = 1 / k_H`` and the track's
  receptance ``alpha_t`` (:func:`wheel_accelerance`; it tends to ``omega^2``
  at low frequency: the wheel follows the roughness).
* **Parametric excitation.** The static load rolling over a track whose
  static receptance varies along the bay (softer between sleepers) deflects
  the rail by ``P alpha_0(x)``; its Fourier coefficients over one bay are an
  equivalent roughness ``r_n`` at the n-th sleeper-passage harmonic
  ``n v / d_s`` (:func:`excitation_roughness`). The amplitude is
  ``A_n(k, v) = |a / r|(n v / d_s) r_n`` (:func:`sleeper_passage_amplitude`),
  the track receptance averaged over the bay.

The amplitude is a resonance curve in speed: the coupled wheel–track
resonance (``sqrt(k_eff / m)``, tens of Hz) is swept by ``f_s = v / d_s``. It
is not a power law in speed and not monotonic in ``k`` at some speeds.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.linalg import solve_banded

from app.analysis._checks import check_positive

__all__ = [
    "TrackParameters",
    "point_receptance",
    "wheel_rail_transfer",
    "wheel_accelerance",
    "excitation_roughness",
    "sleeper_passage_amplitude",
    "resonance_frequency",
]

#: Elements per sleeper bay: the static deflection along a bay is sampled at these points.
_ELEMENTS_PER_BAY = 12
#: Bands either side of the diagonal of the rail's matrices.
_BANDS = 3


@dataclass(frozen=True)
class TrackParameters:
    """A rail on discrete supports and the wheel over it (SI units throughout).

    The defaults are a UIC60 rail on concrete sleepers with the parameters of
    the physics reference runs (``../shared/physics``): pad 200 MN/m and
    28 kNs/m, half-sleeper 177.5 kg, ballast 80 MN/m and 47 kNs/m per rail
    seat, 592 kg unsprung mass, 57 kN static wheel load.

    Attributes
    ----------
    ballast_stiffness : float
        Support (ballast) stiffness per rail seat ``k``, N/m.
    ballast_damping : float
        Ballast damping per rail seat, N s/m.
    pad_stiffness, pad_damping : float
        Rail pad stiffness (N/m) and damping (N s/m).
    sleeper_mass : float
        Mass per rail seat (half a sleeper), kg.
    sleeper_spacing : float
        ``d_s``, m.
    rail_bending_stiffness : float
        ``EI`` of the rail, N m² (UIC60: 210 GPa × 30.38e-6 m⁴).
    rail_shear_stiffness : float
        ``kappa G A`` of the rail, N (0.4 × 81 GPa × 7.67e-3 m²).
    rail_mass : float
        Rail mass per metre, kg/m.
    wheel_mass : float
        Unsprung mass per wheel, kg.
    static_load : float
        Static wheel load ``P``, N.
    hertz_constant : float
        ``G`` of the Hertz law ``delta = G P^(2/3)``, m N^(-2/3).
    n_bays : int
        Bays of the finite rail (the load acts in the central one).
    """

    ballast_stiffness: float = 80e6
    ballast_damping: float = 47e3
    pad_stiffness: float = 200e6
    pad_damping: float = 28e3
    sleeper_mass: float = 177.5
    sleeper_spacing: float = 0.6
    rail_bending_stiffness: float = 210e9 * 30.38e-6
    rail_shear_stiffness: float = 0.4 * 81e9 * 7.67e-3
    rail_mass: float = 60.21
    wheel_mass: float = 592.0
    static_load: float = 57e3
    hertz_constant: float = 4.57e-8
    n_bays: int = 60

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if f.name in ("ballast_damping", "pad_damping"):
                if not getattr(self, f.name) >= 0:
                    raise ValueError(f"{f.name}: must be >= 0, got {getattr(self, f.name)!r}")
            elif f.name != "n_bays":
                check_positive(getattr(self, f.name), f.name)
        if int(self.n_bays) != self.n_bays or self.n_bays < 8:
            raise ValueError(f"n_bays: must be an integer >= 8, got {self.n_bays!r}")

    def replace(self, **changes: float) -> TrackParameters:
        """A copy with some parameters changed (e.g. ``ballast_stiffness=160e6``)."""
        return dataclasses.replace(self, **changes)

    @property
    def contact_stiffness(self) -> float:
        """Linearised Hertz stiffness ``3 P^(1/3) / (2 G)``, N/m."""
        return 1.5 * self.static_load ** (1.0 / 3.0) / self.hertz_constant


@lru_cache(maxsize=64)
def _beam_matrices(params: TrackParameters) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Banded stiffness and mass matrices of the free rail (``scipy.linalg.solve_banded`` layout,
    3 bands either side), the support DOFs and the central sleeper node.

    DOFs are ordered (deflection, rotation) per node, so an element couples
    four consecutive DOFs.
    """
    ne = _ELEMENTS_PER_BAY
    n_el = params.n_bays * ne
    n_nodes = n_el + 1
    lo = params.sleeper_spacing / ne
    ei, kga, m = params.rail_bending_stiffness, params.rail_shear_stiffness, params.rail_mass
    phi = 12.0 * ei / (kga * lo**2)
    ke = ei / ((1.0 + phi) * lo**3) * np.array([
        [12.0, 6 * lo, -12.0, 6 * lo],
        [6 * lo, (4 + phi) * lo**2, -6 * lo, (2 - phi) * lo**2],
        [-12.0, -6 * lo, 12.0, -6 * lo],
        [6 * lo, (2 - phi) * lo**2, -6 * lo, (4 + phi) * lo**2],
    ])
    me = m * lo / 420.0 * np.array([
        [156.0, 22 * lo, 54.0, -13 * lo],
        [22 * lo, 4 * lo**2, 13 * lo, -3 * lo**2],
        [54.0, 13 * lo, 156.0, -22 * lo],
        [-13 * lo, -3 * lo**2, -22 * lo, 4 * lo**2],
    ])
    n = 2 * n_nodes
    kb = np.zeros((2 * _BANDS + 1, n))
    mb = np.zeros((2 * _BANDS + 1, n))
    first = 2 * np.arange(n_el)
    for i in range(4):
        for j in range(4):
            col = first + j
            np.add.at(kb, (_BANDS + i - j, col), ke[i, j])
            np.add.at(mb, (_BANDS + i - j, col), me[i, j])
    supports = 2 * np.arange(0, n_nodes, ne)
    return kb, mb, supports, (params.n_bays // 2) * ne


def _support_stiffness(params: TrackParameters, omega: float) -> complex:
    """Dynamic stiffness of pad – sleeper mass – ballast seen by the rail, N/m."""
    kp = params.pad_stiffness + 1j * omega * params.pad_damping
    kb = params.ballast_stiffness + 1j * omega * params.ballast_damping
    return complex(kp - kp * kp / (kp + kb - omega * omega * params.sleeper_mass))


def point_receptance(
    params: TrackParameters, freqs_hz: np.ndarray, positions_m: np.ndarray
) -> np.ndarray:
    """Point receptance of the rail at positions within a bay, m/N.

    Parameters
    ----------
    params : TrackParameters
        The track.
    freqs_hz : numpy.ndarray
        Frequencies, Hz (>= 0; 0 is the static receptance).
    positions_m : numpy.ndarray
        Load positions after a sleeper, m, multiples of ``d_s / 12`` in
        ``[0, d_s]`` (0 = above a sleeper, ``d_s / 2`` = mid-span).

    Returns
    -------
    numpy.ndarray
        Complex, shape (n_freqs, n_positions).
    """
    f = np.atleast_1d(np.asarray(freqs_hz, dtype=np.float64))
    if f.ndim != 1 or np.any(~np.isfinite(f)) or np.any(f < 0):
        raise ValueError("freqs_hz: must be finite and >= 0 Hz")
    x = np.atleast_1d(np.asarray(positions_m, dtype=np.float64))
    step = params.sleeper_spacing / _ELEMENTS_PER_BAY
    node = np.rint(x / step).astype(np.int64)
    if x.ndim != 1 or np.any(node < 0) or np.any(node > _ELEMENTS_PER_BAY) or \
            not np.allclose(node * step, x, atol=1e-9):
        raise ValueError(f"positions_m: must be multiples of {step:g} m within [0, {params.sleeper_spacing:g}] m")
    kb, mb, supports, centre = _beam_matrices(params)
    dof = 2 * (centre + node)
    rhs = np.zeros((kb.shape[1], dof.size), dtype=np.complex128)
    rhs[dof, np.arange(dof.size)] = 1.0
    out = np.empty((f.size, dof.size), dtype=np.complex128)
    for i, fi in enumerate(f):
        omega = 2.0 * np.pi * fi
        band = (kb - (omega * omega) * mb).astype(np.complex128)
        band[_BANDS, supports] += _support_stiffness(params, omega)
        sol = solve_banded((_BANDS, _BANDS), band, rhs, check_finite=False)
        out[i] = sol[dof, np.arange(dof.size)]
    return out


def _bay_positions(params: TrackParameters) -> np.ndarray:
    return np.arange(_ELEMENTS_PER_BAY) * params.sleeper_spacing / _ELEMENTS_PER_BAY


def wheel_rail_transfer(
    params: TrackParameters, freqs_hz: np.ndarray, position_m: float | None = None
) -> np.ndarray:
    """Wheel acceleration per unit roughness at the contact, ``a / r`` (complex, m/s² per m).

    ``a / r = (1 / m) / (alpha_w + alpha_c + alpha_t)`` for a harmonic
    roughness ``r e^(i omega t)`` (up positive, a dip is negative) under the
    wheel: at low frequency ``-omega^2`` (the wheel follows the rail), at high
    frequency ``1 / (m (alpha_c + alpha_t))`` (the contact and the rail give).
    Its inverse, ``m (alpha_w + alpha_c + alpha_t)``, turns a measured
    acceleration back into the roughness that caused it.

    Parameters
    ----------
    params : TrackParameters
        Track and wheel.
    freqs_hz : numpy.ndarray
        Frequencies, Hz (> 0).
    position_m : float, optional
        Wheel position after a sleeper, m (a multiple of ``d_s / 12``); default
        the track receptance averaged over the bay.

    Returns
    -------
    numpy.ndarray
        Complex, the shape of ``freqs_hz`` (at least 1-D).
    """
    f = np.atleast_1d(np.asarray(freqs_hz, dtype=np.float64))
    if np.any(~(f > 0)):
        raise ValueError("freqs_hz: must be > 0 Hz")
    pos = _bay_positions(params) if position_m is None else np.array([float(position_m)])
    alpha_t = point_receptance(params, f, pos).mean(axis=1)
    omega2 = (2.0 * np.pi * f) ** 2
    alpha_w = -1.0 / (params.wheel_mass * omega2)
    return 1.0 / (params.wheel_mass * (alpha_w + 1.0 / params.contact_stiffness + alpha_t))


def wheel_accelerance(
    params: TrackParameters, freqs_hz: np.ndarray, position_m: float | None = None
) -> np.ndarray:
    """Wheel acceleration per unit roughness at the contact, ``|a / r|`` (m/s² per m).

    The magnitude of :func:`wheel_rail_transfer` (parameters there).
    """
    return np.abs(wheel_rail_transfer(params, freqs_hz, position_m))


def excitation_roughness(params: TrackParameters, n_harmonics: int = 3) -> np.ndarray:
    """Equivalent roughness of the parametric excitation at harmonics 1 … n, m (amplitudes).

    The Fourier amplitudes over one bay of the static rail deflection under the
    wheel, ``P alpha_0(x)``.
    """
    if int(n_harmonics) != n_harmonics or not 1 <= n_harmonics <= _ELEMENTS_PER_BAY // 2 - 1:
        raise ValueError(f"n_harmonics: must be an integer in [1, {_ELEMENTS_PER_BAY // 2 - 1}]")
    u = params.static_load * point_receptance(params, np.zeros(1), _bay_positions(params))[0].real
    coef = np.fft.rfft(u) / u.size * 2.0
    return np.abs(coef[1 : int(n_harmonics) + 1])


def sleeper_passage_amplitude(
    params: TrackParameters, speed_mps: np.ndarray, harmonic: int = 1
) -> np.ndarray:
    """Axle-box acceleration amplitude at the sleeper-passage harmonic ``n v / d_s``, m/s².

    Parameters
    ----------
    params : TrackParameters
        Track and wheel (``params.ballast_stiffness`` is ``k``).
    speed_mps : numpy.ndarray
        Speeds, m/s (> 0).
    harmonic : int
        1 = the sleeper-passage order ``v / d_s``, 2 and 3 its harmonics.
    """
    v = np.asarray(speed_mps, dtype=np.float64)
    if np.any(~(v > 0)) or np.any(~np.isfinite(v)):
        raise ValueError("speed_mps: must be finite and > 0 m/s")
    if harmonic not in (1, 2, 3):
        raise ValueError(f"harmonic: must be 1, 2 or 3, got {harmonic!r}")
    r = excitation_roughness(params, 3)[harmonic - 1]
    freqs = harmonic * v.ravel() / params.sleeper_spacing
    return (wheel_accelerance(params, freqs) * r).reshape(v.shape)


def resonance_frequency(params: TrackParameters, band_hz: tuple[float, float] = (20.0, 150.0),
                        step_hz: float = 0.5) -> float:
    """The coupled wheel–track resonance: the lowest local maximum of ``|a / r|`` in ``band_hz``, Hz.

    NaN when ``|a / r|`` has no local maximum in the band.
    """
    lo, hi = band_hz
    if not 0 < lo < hi:
        raise ValueError(f"band_hz: must satisfy 0 < low < high, got {band_hz!r}")
    check_positive(step_hz, "step_hz")
    f = np.arange(lo, hi + step_hz / 2, step_hz)
    h = wheel_accelerance(params, f)
    peaks = np.flatnonzero((h[1:-1] > h[:-2]) & (h[1:-1] >= h[2:])) + 1
    return float(f[peaks[0]]) if peaks.size else float("nan")
