"""The rail surface of a simulated line: random roughness, welds and joints, grinding.

Everything here is fixed to the track: the height of a rail's running surface
at a track position ``x`` (m on the km axis, ``1000 * km``) is a function of
the line alone — the same in every run of the line — until a grinding action
changes it from its date on.

Roughness
---------
Sato's short-wave rail irregularity spectrum (one-sided, m² per rad/m,
``Omega = 2 pi / lambda`` in rad/m)::

    S(Omega) = A / Omega**3,      lambda_min <= 2 pi / Omega <= lambda_max

with ``A = 4.15e-8`` ("good rail", the value the vehicle–track literature
quotes, e.g. Zhai) and ``lambda`` = 0.05 … 3 m: 69 µm RMS over the band,
26.6 µm for 0.3–1.2 m (around the 0.6 m sleeper spacing). The same spectrum
as the physics reference runs (``../shared/physics/README.md``).

It is made by filtering white noise on a grid of :data:`ROUGHNESS_STEP_M`
(2 mm): cell ``i = floor(x / step)`` takes its white value from a generator
seeded by ``(seed, rail, generation, i // TILE)``, so any stretch of the line
is generated alone and agrees with every other stretch that overlaps it
(stationary, no seams). The filter's amplitude response is
``sqrt(pi S(2 pi |kappa|) / step)`` (``kappa`` in cycles/m) with short
raised-cosine edges, zero phase. A run that samples the rail more coarsely
than the shortest wavelength allows (low sample rate, high speed) asks for a
longer ``min_wavelength_m``: the same white noise through a narrower filter,
so the realisation is the same at the wavelengths that remain.

Welds and joints
----------------
Isolated dips of the running surface (:class:`TrackImpact`): a dipped weld is
a cosine dip (e.g. 0.3 mm over 1 m), a dipped joint a shorter, deeper one.
They are added to the roughness.

Grinding
--------
A :class:`RailGrinding` replaces the roughness over its extent, from its date
on, by a new realisation (the next *generation*) scaled by
``roughness_scale`` (ground rail is smoother), with 1 m crossfades at the
extent's ends. Welds stay.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from scipy.signal import oaconvolve

__all__ = [
    "ROUGHNESS_STEP_M",
    "SATO_A_GOOD_RAIL",
    "RoughnessSpectrum",
    "TrackImpact",
    "RailGrinding",
    "RailSurface",
    "generate_surface",
    "as_date",
]

#: Grid step of the generated rail profile, m.
ROUGHNESS_STEP_M = 0.002
#: Cells per white-noise tile (each tile has its own seed).
_TILE = 1 << 16
#: Half length of the roughness filter's kernel, cells (32.8 m: the 3 m band edge decays in it).
_KERNEL_HALF = 1 << 14
#: Relative width of the raised-cosine band edges (in wavelength).
_EDGE = 0.1
#: Sato's A of "good rail", m² rad² / m (one-sided S = A / Omega³ in m² per rad/m).
SATO_A_GOOD_RAIL = 4.15e-8
#: Length of the crossfade at the ends of a ground stretch, m.
_GRIND_FADE_M = 1.0


def as_date(value: dt.date | dt.datetime | str) -> dt.date:
    """A calendar date from a date, a datetime or an ISO string (its date part)."""
    if isinstance(value, dt.datetime):
        return value.date()
    if isinstance(value, dt.date):
        return value
    text = str(value).strip()
    try:
        return dt.datetime.fromisoformat(text).date() if len(text) > 10 else dt.date.fromisoformat(text)
    except ValueError:
        raise ValueError(f"date: not an ISO date or datetime: {value!r}") from None


@dataclass(frozen=True)
class RoughnessSpectrum:
    """Sato's spectrum ``S(Omega) = A / Omega**3`` over a wavelength band, times ``scale**2``.

    Attributes
    ----------
    a : float
        ``A``, m² rad²/m (default :data:`SATO_A_GOOD_RAIL`).
    wavelength_m : (float, float)
        Shortest and longest wavelength, m (default 0.05 … 3).
    scale : float
        Amplitude factor (the physics runs' "severe" rail is 3).
    """

    a: float = SATO_A_GOOD_RAIL
    wavelength_m: tuple[float, float] = (0.05, 3.0)
    scale: float = 1.0

    def __post_init__(self) -> None:
        lo, hi = (float(x) for x in self.wavelength_m)
        if not (math.isfinite(self.a) and self.a > 0):
            raise ValueError(f"a: must be a finite number > 0, got {self.a!r}")
        if not (4 * ROUGHNESS_STEP_M <= lo < hi <= 20.0):
            raise ValueError(f"wavelength_m: must satisfy {4 * ROUGHNESS_STEP_M:g} <= min < max <= 20 m, "
                             f"got {self.wavelength_m!r}")
        if not (math.isfinite(self.scale) and self.scale >= 0):
            raise ValueError(f"scale: must be a finite number >= 0, got {self.scale!r}")
        object.__setattr__(self, "wavelength_m", (lo, hi))

    def psd(self, omega: np.ndarray) -> np.ndarray:
        """One-sided ``S(Omega)`` in the band (0 outside), m² per rad/m."""
        om = np.asarray(omega, dtype=np.float64)
        lo, hi = self.wavelength_m
        inside = (om >= 2 * np.pi / hi) & (om <= 2 * np.pi / lo)
        with np.errstate(divide="ignore"):
            return np.where(inside, self.scale**2 * self.a / np.maximum(om, 1e-300) ** 3, 0.0)

    def rms(self, wavelength_m: tuple[float, float] | None = None) -> float:
        """RMS height over a wavelength band (default the whole band), m (closed form)."""
        lo, hi = self.wavelength_m if wavelength_m is None else wavelength_m
        lo, hi = max(lo, self.wavelength_m[0]), min(hi, self.wavelength_m[1])
        if lo >= hi:
            return 0.0
        om1, om2 = 2 * np.pi / hi, 2 * np.pi / lo
        return float(self.scale * math.sqrt(self.a / 2.0 * (om1**-2 - om2**-2)))


@dataclass(frozen=True)
class TrackImpact:
    """An isolated dip of one rail's running surface (a dipped weld or joint), cosine-shaped.

    ``height(x) = -depth_m / 2 * (1 + cos(2 pi (x - track_m) / length_m))`` for
    ``|x - track_m| < length_m / 2``, 0 elsewhere.

    Attributes
    ----------
    track_m : float
        Centre, m on the km axis.
    length_m : float
        Length of the dip, m.
    depth_m : float
        Depth, m (> 0; the surface goes down by this much at the centre).
    side : int
        Rail: 1 (right) or 2 (left).
    kind : str
        ``"weld"`` or ``"joint"``.
    """

    track_m: float
    length_m: float
    depth_m: float
    side: int
    kind: str = "weld"

    def __post_init__(self) -> None:
        if self.side not in (1, 2):
            raise ValueError(f"side: must be 1 or 2, got {self.side!r}")
        if not (math.isfinite(self.length_m) and 0 < self.length_m <= 10):
            raise ValueError(f"length_m: must be in (0, 10] m, got {self.length_m!r}")
        if not (math.isfinite(self.depth_m) and 0 < self.depth_m < 0.01):
            raise ValueError(f"depth_m: must be in (0, 0.01) m, got {self.depth_m!r}")
        if self.kind not in ("weld", "joint"):
            raise ValueError(f"kind: must be 'weld' or 'joint', got {self.kind!r}")

    def height(self, x: np.ndarray) -> np.ndarray:
        """Surface height the dip adds at positions ``x`` (m), m (<= 0)."""
        u = (np.asarray(x, dtype=np.float64) - self.track_m) / self.length_m
        return np.where(np.abs(u) < 0.5, -0.5 * self.depth_m * (1.0 + np.cos(2 * np.pi * u)), 0.0)


@dataclass(frozen=True)
class RailGrinding:
    """A grinding action: from ``date`` on, the roughness over the extent is a new, smoother one.

    Attributes
    ----------
    track_from_m, track_to_m : float
        Extent, m on the km axis (both rails).
    date : str
        ISO date of the action.
    roughness_scale : float
        Amplitude of the new roughness relative to the spectrum's (default 0.3).
    """

    track_from_m: float
    track_to_m: float
    date: str
    roughness_scale: float = 0.3

    def __post_init__(self) -> None:
        if not (math.isfinite(self.track_from_m) and math.isfinite(self.track_to_m)
                and self.track_from_m < self.track_to_m):
            raise ValueError("track_from_m/track_to_m: must be finite with from < to")
        object.__setattr__(self, "date", as_date(self.date).isoformat())
        if not (math.isfinite(self.roughness_scale) and self.roughness_scale >= 0):
            raise ValueError(f"roughness_scale: must be >= 0, got {self.roughness_scale!r}")


@lru_cache(maxsize=16)
def _kernel(spectrum: RoughnessSpectrum, min_wavelength_m: float) -> np.ndarray:
    """Zero-phase FIR (2 * _KERNEL_HALF + 1 taps) turning unit white noise into the roughness."""
    n = 2 * _KERNEL_HALF
    kappa = np.fft.rfftfreq(n, ROUGHNESS_STEP_M)
    lo = max(spectrum.wavelength_m[0], float(min_wavelength_m))
    hi = spectrum.wavelength_m[1]
    with np.errstate(divide="ignore"):
        lam = np.where(kappa > 0, 1.0 / np.maximum(kappa, 1e-300), np.inf)
    # raised-cosine edges in log wavelength, centred on the band edges (half power there)
    def edge(u: np.ndarray) -> np.ndarray:  # u: log distance inside the band, in units of the edge width
        return np.where(u >= 0.5, 1.0, np.where(u <= -0.5, 0.0, 0.5 * (1.0 + np.sin(np.pi * u))))
    w = np.log1p(_EDGE)
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = edge(np.log(lam / lo) / w) * edge(np.log(hi / lam) / w)
    omega = 2.0 * np.pi * np.maximum(kappa, kappa[1])
    psd = spectrum.scale**2 * spectrum.a / omega**3  # S(Omega) without band limits; the edges cut it
    amp = np.sqrt(np.pi * psd / ROUGHNESS_STEP_M) * gain
    amp[0] = 0.0
    k = np.fft.fftshift(np.fft.irfft(amp, n))
    taper = np.hanning(n + 1)[:n]  # the band edges are smooth: the kernel has decayed well before its ends
    k = k * np.sqrt(taper)
    out = np.concatenate([k, k[:1]])  # symmetric, 2 * half + 1 taps (k[0] ~ 0 after the taper)
    out.setflags(write=False)
    return out


def _white(seed: int, side: int, generation: int, i0: int, i1: int) -> np.ndarray:
    """Unit white noise of cells ``i0 … i1 - 1`` (tile-seeded: stretches agree where they overlap)."""
    out = np.empty(i1 - i0)
    t0, t1 = i0 // _TILE, (i1 - 1) // _TILE
    for t in range(t0, t1 + 1):
        a, b = max(i0, t * _TILE), min(i1, (t + 1) * _TILE)
        key = t + (1 << 40)  # tiles left of 0 too
        tile = np.random.default_rng([int(seed), int(side), int(generation), key]).standard_normal(_TILE)
        out[a - i0 : b - i0] = tile[a - t * _TILE : b - t * _TILE]
    return out


@dataclass(frozen=True)
class RailSurface:
    """The running surfaces of both rails of a line (see the module docstring).

    Attributes
    ----------
    seed : int
        Seed of the random roughness.
    spectrum : RoughnessSpectrum or None
        Roughness spectrum; None: no random roughness (welds and joints only).
    impacts : tuple of TrackImpact
        Welds and joints, ascending position.
    grindings : tuple of RailGrinding
        Grinding actions, by date.
    """

    seed: int
    spectrum: RoughnessSpectrum | None = field(default_factory=RoughnessSpectrum)
    impacts: tuple[TrackImpact, ...] = ()
    grindings: tuple[RailGrinding, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "impacts", tuple(sorted(self.impacts, key=lambda w: (w.track_m, w.side))))
        object.__setattr__(self, "grindings", tuple(sorted(self.grindings, key=lambda g: g.date)))

    def with_grindings(self, grindings: tuple[RailGrinding, ...] | list[RailGrinding]) -> RailSurface:
        """The same surface with these grinding actions added."""
        return replace(self, grindings=(*self.grindings, *grindings))

    def impacts_between(self, x_from: float, x_to: float, side: int | None = None) -> tuple[TrackImpact, ...]:
        """Welds and joints whose centre lies in ``[x_from, x_to]`` (m), of one rail or both."""
        return tuple(w for w in self.impacts
                     if x_from <= w.track_m <= x_to and (side is None or w.side == side))

    def roughness(self, side: int, x_from: float, x_to: float, on: dt.date | str | None = None,
                  *, min_wavelength_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Random roughness of one rail on the grid over ``[x_from, x_to]`` on a date.

        Parameters
        ----------
        side : int
            1 (right) or 2 (left).
        x_from, x_to : float
            Stretch, m on the km axis.
        on : date or str, optional
            Date of the run (grinding actions up to it apply); None: before any.
        min_wavelength_m : float
            Leave out wavelengths shorter than this, m (coarse sampling).

        Returns
        -------
        x, height : numpy.ndarray
            Grid positions (multiples of :data:`ROUGHNESS_STEP_M`, m) and heights, m.
        """
        if side not in (1, 2):
            raise ValueError(f"side: must be 1 or 2, got {side!r}")
        if not (math.isfinite(x_from) and math.isfinite(x_to) and x_from < x_to):
            raise ValueError("x_from/x_to: must be finite with from < to")
        i0 = math.floor(x_from / ROUGHNESS_STEP_M)
        i1 = math.ceil(x_to / ROUGHNESS_STEP_M) + 1
        x = np.arange(i0, i1) * ROUGHNESS_STEP_M
        if self.spectrum is None:
            return x, np.zeros(x.size)
        when = None if on is None else as_date(on)
        done = [g for g in self.grindings if when is not None and as_date(g.date) <= when]
        h = self._realisation(side, 0, i0, i1, 1.0, min_wavelength_m)
        for gen, g in enumerate(self.grindings, start=1):
            if g not in done or g.track_to_m < x[0] or g.track_from_m > x[-1]:
                continue
            fade = np.clip(np.minimum(x - g.track_from_m, g.track_to_m - x) / _GRIND_FADE_M + 0.5, 0.0, 1.0)
            inside = fade > 0
            if not inside.any():
                continue
            j0, j1 = int(np.argmax(inside)), int(inside.size - np.argmax(inside[::-1]))
            new = self._realisation(side, gen, i0 + j0, i0 + j1, g.roughness_scale, min_wavelength_m)
            w = 0.5 * (1.0 - np.cos(np.pi * fade[j0:j1]))
            h[j0:j1] = (1.0 - w) * h[j0:j1] + w * new
        return x, h

    def _realisation(self, side: int, generation: int, i0: int, i1: int, scale: float,
                     min_wavelength_m: float) -> np.ndarray:
        assert self.spectrum is not None
        k = _kernel(self.spectrum, float(min_wavelength_m))
        half = (k.size - 1) // 2
        white = _white(self.seed, side, generation, i0 - half, i1 + half)
        return scale * oaconvolve(white, k, mode="valid")

    def profile(self, side: int, x_from: float, x_to: float, on: dt.date | str | None = None, *,
                roughness: bool = True, impacts: bool = True,
                min_wavelength_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Height of one rail's running surface on the grid over ``[x_from, x_to]``, m.

        The random roughness (:meth:`roughness`, if ``roughness``) plus the
        welds and joints of the rail (if ``impacts``).
        """
        if roughness:
            x, h = self.roughness(side, x_from, x_to, on, min_wavelength_m=min_wavelength_m)
        else:
            i0 = math.floor(x_from / ROUGHNESS_STEP_M)
            x = np.arange(i0, math.ceil(x_to / ROUGHNESS_STEP_M) + 1) * ROUGHNESS_STEP_M
            h = np.zeros(x.size)
        if impacts:
            for w in self.impacts_between(x[0] - 5.0, x[-1] + 5.0, side):
                m = np.abs(x - w.track_m) < 0.5 * w.length_m
                h[m] += w.height(x[m])
        return x, h


def generate_surface(
    track_from_m: float,
    track_to_m: float,
    seed: int | np.random.Generator = 0,
    *,
    spectrum: RoughnessSpectrum | None = None,
    weld_spacing_m: tuple[float, float] | None = (100.0, 200.0),
    weld_length_m: tuple[float, float] = (0.8, 1.2),
    weld_depth_m: tuple[float, float] = (0.2e-3, 0.4e-3),
    joint_spacing_m: tuple[float, float] | None = None,
    joint_length_m: tuple[float, float] = (0.3, 0.5),
    joint_depth_m: tuple[float, float] = (0.4e-3, 0.8e-3),
) -> RailSurface:
    """A random rail surface: roughness seed, welds (both rails) and, optionally, joints.

    Parameters
    ----------
    track_from_m, track_to_m : float
        Extent of the line, m on the km axis.
    seed : int or numpy.random.Generator
        Randomness (a generator gives the roughness seed and the weld draws).
    spectrum : RoughnessSpectrum, optional
        Roughness spectrum (default :class:`RoughnessSpectrum`: Sato, good rail).
    weld_spacing_m : (float, float) or None
        Distance between successive welds, uniform in this range (default 100 …
        200 m); None: no welds. Each weld dips both rails at the same position,
        each rail with its own depth and length.
    weld_length_m, weld_depth_m : (float, float)
        Ranges of a weld's dip length and depth, m (default 0.8 … 1.2 m,
        0.2 … 0.4 mm).
    joint_spacing_m : (float, float) or None
        Distance between dipped joints (both rails), default None: continuously
        welded rail.
    joint_length_m, joint_depth_m : (float, float)
        Ranges of a joint's dip length and depth, m.

    Returns
    -------
    RailSurface
    """
    if not (math.isfinite(track_from_m) and math.isfinite(track_to_m) and track_from_m < track_to_m):
        raise ValueError("track_from_m/track_to_m: must be finite with from < to")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    rough_seed = int(rng.integers(0, 2**62))
    impacts: list[TrackImpact] = []
    for kind, spacing, lengths, depths in (("weld", weld_spacing_m, weld_length_m, weld_depth_m),
                                           ("joint", joint_spacing_m, joint_length_m, joint_depth_m)):
        if spacing is None:
            continue
        lo, hi = (float(s) for s in spacing)
        if not 0 < lo <= hi:
            raise ValueError(f"{kind}_spacing_m: must satisfy 0 < min <= max, got {spacing!r}")
        x = track_from_m + float(rng.uniform(0.0, lo))
        while x < track_to_m:
            for side in (1, 2):
                impacts.append(TrackImpact(x, float(rng.uniform(*lengths)), float(rng.uniform(*depths)),
                                           side, kind))
            x += float(rng.uniform(lo, hi))
    return RailSurface(rough_seed, RoughnessSpectrum() if spectrum is None else spectrum, tuple(impacts))
