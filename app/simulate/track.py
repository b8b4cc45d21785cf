"""The simulated line: superstructure sections and sleeper-passage stiffness along the km axis.

Positions are *track positions* on the line km axis in metres,
``track_m = 1000 * km`` (the frame of the 25 cm profile bins,
``bin = floor(track_m / 0.25)``). A :class:`LineModel` is independent of any
run, so several runs (other speeds, seeds, directions) can pass over the same
line.

Sleeper-passage amplitude model
-------------------------------
At a track position ``x`` on rail side ``side`` the sleeper-passage
acceleration amplitude at speed ``v`` is::

    a_s = K_type(x) * f_side(x) * (v / v_ref) ** alpha

``K_type`` is the amplitude at ``v_ref`` of the superstructure type
(:data:`SUPERSTRUCTURE_AMPLITUDE`, stiffer track → higher amplitude) and
``f_side`` the local stiffness factor: a mild smooth random variation (per rail,
correlated between rails) times the local anomalies (soft/hard spots).
``K_type * f_side`` is tabulated at the centres of the 25 cm bins and linearly
interpolated between them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from app.simulate.surface import RailSurface, generate_surface

__all__ = [
    "SUPERSTRUCTURE_TYPES",
    "RANDOM_SECTION_TYPES",
    "SUPERSTRUCTURE_AMPLITUDE",
    "SUPERSTRUCTURE_LABELS",
    "BIN_LENGTH_M",
    "TrackSection",
    "StiffnessAnomaly",
    "LineModel",
    "generate_line",
]

#: Superstructure types, index = type code (a new type is appended: the codes of stored truths stay valid).
SUPERSTRUCTURE_TYPES: tuple[str, ...] = ("slab", "b91_no_pads", "b91_pads", "timber")
#: The types a random line's sections are drawn from (the first three: lines drawn before ``timber`` existed
#: stay the same).
RANDOM_SECTION_TYPES: tuple[str, ...] = ("slab", "b91_no_pads", "b91_pads")
#: Sleeper-passage acceleration amplitude at v_ref per type, m/s².
SUPERSTRUCTURE_AMPLITUDE: dict[str, float] = {"slab": 3.0, "b91_no_pads": 1.8, "b91_pads": 0.8, "timber": 1.2}
#: Human-readable names.
SUPERSTRUCTURE_LABELS: dict[str, str] = {
    "slab": "slab track (L77-B)",
    "b91_no_pads": "B91 concrete sleepers without under-sleeper pads",
    "b91_pads": "B91 concrete sleepers with under-sleeper pads (Sylomer)",
    "timber": "timber sleepers on ballast",
}
#: Profile bin length, m.
BIN_LENGTH_M = 0.25


class _KmExtent:
    """``km_from`` / ``km_to`` of a stretch ``[track_from_m, track_to_m]`` (m on the km axis)."""

    track_from_m: float
    track_to_m: float

    @property
    def km_from(self) -> float:
        """Start, km."""
        return self.track_from_m / 1000.0

    @property
    def km_to(self) -> float:
        """End, km."""
        return self.track_to_m / 1000.0


@dataclass(frozen=True)
class TrackSection(_KmExtent):
    """A stretch of one superstructure type, ``[track_from_m, track_to_m)`` on the km axis (m)."""

    track_from_m: float
    track_to_m: float
    type: str


@dataclass(frozen=True)
class StiffnessAnomaly(_KmExtent):
    """A short local stiffness anomaly (both rails).

    The stiffness factor is multiplied by ``1 + (factor - 1) * w(x)`` with
    ``w`` = 1 on the core and raised-cosine tapers of ``taper_m`` inside
    ``[track_from_m, track_to_m]`` (m on the km axis).
    """

    track_from_m: float
    track_to_m: float
    factor: float
    taper_m: float = 10.0
    kind: str = "soft spot"

    def weight(self, x: np.ndarray) -> np.ndarray:
        """Shape ``w(x)`` in [0, 1] of the anomaly at track positions ``x`` (m)."""
        x = np.asarray(x, dtype=np.float64)
        a, b, t = self.track_from_m, self.track_to_m, max(self.taper_m, 1e-9)
        up = np.clip((x - a) / t, 0.0, 1.0)
        down = np.clip((b - x) / t, 0.0, 1.0)
        return 0.5 * (1.0 - np.cos(np.pi * np.minimum(up, down)))


@dataclass(frozen=True)
class LineModel:
    """Superstructure and stiffness of a line on a 25 cm grid.

    Attributes
    ----------
    first_bin : int
        Bin index of the first grid cell (``floor(track_m / bin_length)``).
    type_code : numpy.ndarray
        int8 (nb,): superstructure type code per bin (index into
        :data:`SUPERSTRUCTURE_TYPES`).
    factor : numpy.ndarray
        float (2, nb): local stiffness factor per bin, row 0 = rail side 1
        (right), row 1 = side 2 (left).
    sections : tuple of TrackSection
        Section table, ascending track position.
    anomalies : tuple of StiffnessAnomaly
        Local anomalies (already included in ``factor``).
    amplitude_vref : dict[str, float]
        ``K_type``, m/s² at ``v_ref``.
    bin_length : float
        Grid step, m (0.25).
    surface : RailSurface or None
        The running surfaces of the rails (roughness, welds, joints, grinding;
        :mod:`app.simulate.surface`); None: smooth rails.
    """

    first_bin: int
    type_code: np.ndarray
    factor: np.ndarray
    sections: tuple[TrackSection, ...]
    anomalies: tuple[StiffnessAnomaly, ...] = ()
    amplitude_vref: dict[str, float] = field(default_factory=lambda: dict(SUPERSTRUCTURE_AMPLITUDE))
    bin_length: float = BIN_LENGTH_M
    surface: RailSurface | None = None

    def __post_init__(self) -> None:
        nb = self.type_code.shape[0]
        if self.factor.shape != (2, nb):
            raise ValueError(f"factor must have shape (2, {nb}), got {self.factor.shape}")
        missing = set(SUPERSTRUCTURE_TYPES) - set(self.amplitude_vref)
        if missing:
            raise ValueError(f"amplitude_vref lacks types {sorted(missing)}")

    # --- grid -------------------------------------------------------------
    @property
    def n_bins(self) -> int:
        """Number of grid cells."""
        return int(self.type_code.shape[0])

    @property
    def track_from_m(self) -> float:
        """Start of the grid, m on the km axis."""
        return self.first_bin * self.bin_length

    @property
    def track_to_m(self) -> float:
        """End of the grid, m on the km axis."""
        return (self.first_bin + self.n_bins) * self.bin_length

    def bins(self) -> np.ndarray:
        """Bin indices of the grid cells."""
        return np.arange(self.first_bin, self.first_bin + self.n_bins, dtype=np.int64)

    def centres(self) -> np.ndarray:
        """Bin centres, m on the km axis."""
        return (self.bins() + 0.5) * self.bin_length

    def covers(self, lo: float, hi: float) -> bool:
        """Whether track positions ``[lo, hi]`` (m) lie on the grid."""
        return self.track_from_m <= lo and hi <= self.track_to_m

    # --- values ---------------------------------------------------------------
    def amplitude_grid(self, side: int) -> np.ndarray:
        """``K_type * factor`` per bin of rail ``side`` (1 or 2), m/s² at v_ref."""
        k = np.array([self.amplitude_vref[t] for t in SUPERSTRUCTURE_TYPES])
        return k[self.type_code] * self.factor[_side_row(side)]

    def amplitude_at_vref(self, track_m: np.ndarray, side: int) -> np.ndarray:
        """Sleeper-passage amplitude at v_ref at track positions (m), m/s² (linear between centres)."""
        return np.interp(track_m, self.centres(), self.amplitude_grid(side))

    def stiffness_factor(self, track_m: np.ndarray, side: int) -> np.ndarray:
        """Local stiffness factor at track positions (m), linear between centres."""
        return np.interp(track_m, self.centres(), self.factor[_side_row(side)])

    def type_at(self, track_m: np.ndarray) -> np.ndarray:
        """Superstructure type code of the bins holding track positions (m)."""
        idx = np.floor(np.asarray(track_m) / self.bin_length).astype(np.int64) - self.first_bin
        if np.any((idx < 0) | (idx >= self.n_bins)):
            raise ValueError("track_m: position outside the line model")
        return self.type_code[idx]

    def section_table(self) -> list[dict[str, float | str]]:
        """Sections as rows ``{km_from, km_to, track_from_m, track_to_m, type}``."""
        return [
            {
                "km_from": s.km_from,
                "km_to": s.km_to,
                "track_from_m": s.track_from_m,
                "track_to_m": s.track_to_m,
                "type": s.type,
            }
            for s in self.sections
        ]


def _side_row(side: int) -> int:
    if side not in (1, 2):
        raise ValueError(f"side must be 1 (right) or 2 (left), got {side!r}")
    return side - 1


def _smooth_noise(rng: np.random.Generator, n: int, corr_bins: float) -> np.ndarray:
    """Unit-variance Gaussian noise with a Gaussian autocorrelation of ``corr_bins``."""
    half = int(np.ceil(4 * corr_bins))
    k = np.arange(-half, half + 1)
    kernel = np.exp(-0.5 * (k / corr_bins) ** 2)
    kernel /= np.sqrt(np.sum(kernel**2))
    white = rng.standard_normal(n + 2 * half)
    return np.convolve(white, kernel, mode="valid")


def _make_sections(
    rng: np.random.Generator, lo: float, hi: float, length_range: tuple[float, float]
) -> list[TrackSection]:
    sections: list[TrackSection] = []
    x = lo
    prev = None
    while x < hi:
        length = rng.uniform(*length_range)
        choices = [t for t in RANDOM_SECTION_TYPES if t != prev]
        typ = choices[int(rng.integers(len(choices)))]
        end = min(x + length, hi)
        if hi - end < 0.5 * length_range[0]:  # avoid a tiny last section
            end = hi
        sections.append(TrackSection(x, end, typ))
        prev, x = typ, end
    return sections


def _place_anomalies(
    rng: np.random.Generator,
    sections: Sequence[TrackSection],
    lo: float,
    hi: float,
    count: int,
    length_range: tuple[float, float],
) -> list[StiffnessAnomaly]:
    out: list[StiffnessAnomaly] = []
    margin = 20.0
    for i in range(count):
        soft = i % 2 == 0
        for _ in range(500):
            length = rng.uniform(*length_range)
            a = rng.uniform(lo, hi - length) if hi - lo > length else None
            if a is None:
                break
            b = a + length
            inside = any(
                s.track_from_m + margin <= a and b <= s.track_to_m - margin for s in sections
            )
            apart = all(b + 50 <= o.track_from_m or o.track_to_m + 50 <= a for o in out)
            if inside and apart:
                factor = rng.uniform(0.45, 0.6) if soft else rng.uniform(1.4, 1.7)
                out.append(
                    StiffnessAnomaly(
                        a, b, float(factor), 10.0, "soft spot" if soft else "hard spot"
                    )
                )
                break
    return sorted(out, key=lambda o: o.track_from_m)


def generate_line(
    track_from_m: float,
    track_to_m: float,
    seed: int | np.random.Generator = 0,
    *,
    section_length_m: tuple[float, float] = (300.0, 1500.0),
    variation_std: float = 0.08,
    correlation_m: float = 20.0,
    rail_correlation: float = 0.7,
    n_anomalies: int | None = None,
    anomaly_range_m: tuple[float, float] | None = None,
    anomaly_length_m: tuple[float, float] = (100.0, 200.0),
    amplitude_vref: dict[str, float] | None = None,
    sections: Sequence[TrackSection] | None = None,
    anomalies: Sequence[StiffnessAnomaly] | None = None,
    surface: bool | RailSurface | None = None,
) -> LineModel:
    """Generate a random line.

    Parameters
    ----------
    track_from_m, track_to_m : float
        Extent on the km axis, m (``1000 * km``), ``track_from_m < track_to_m``.
    seed : int or numpy.random.Generator
        Randomness.
    section_length_m : (float, float)
        Range of section lengths, m (default 300 … 1500 m).
    variation_std : float
        Standard deviation of the mild smooth stiffness variation (default 0.08).
    correlation_m : float
        Correlation length of that variation, m (default 20 m).
    rail_correlation : float
        Correlation of the variation between the two rails, in [0, 1].
    n_anomalies : int or None
        Number of local anomalies (soft, hard, soft, …); default one per 3 km,
        at least one. Fewer are placed if they do not fit (each lies inside one
        section, 20 m from its ends, 50 m from the others).
    anomaly_range_m : (float, float) or None
        Where anomalies may lie, m on the km axis (default the whole line).
    anomaly_length_m : (float, float)
        Range of anomaly lengths, m (default 100 … 200 m).
    amplitude_vref : dict, optional
        ``K_type`` per superstructure type, m/s² (default
        :data:`SUPERSTRUCTURE_AMPLITUDE`).
    sections, anomalies : sequence, optional
        Use these instead of random ones.
    surface : bool or RailSurface, optional
        The rails' running surface: None/False smooth rails, True a random one
        (:func:`app.simulate.surface.generate_surface`, drawn after everything
        else so the rest of the line does not depend on it), or this one.

    Returns
    -------
    LineModel
    """
    if not (np.isfinite(track_from_m) and np.isfinite(track_to_m) and track_from_m < track_to_m):
        raise ValueError(
            f"track_from_m/track_to_m must be finite with from < to, got {track_from_m!r}, {track_to_m!r}"
        )
    if not 0.0 <= variation_std <= 0.3:
        raise ValueError(f"variation_std must be in [0, 0.3], got {variation_std!r}")
    if not correlation_m > 0:
        raise ValueError(f"correlation_m must be > 0 m, got {correlation_m!r}")
    if not 0.0 <= rail_correlation <= 1.0:
        raise ValueError(f"rail_correlation must be in [0, 1], got {rail_correlation!r}")
    lo_len, hi_len = section_length_m
    if not 0 < lo_len <= hi_len:
        raise ValueError(f"section_length_m must satisfy 0 < min <= max, got {section_length_m!r}")
    amps = dict(SUPERSTRUCTURE_AMPLITUDE if amplitude_vref is None else amplitude_vref)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    bl = BIN_LENGTH_M
    first_bin = int(np.floor(track_from_m / bl))
    last_bin = int(np.ceil(track_to_m / bl))
    nb = last_bin - first_bin
    lo, hi = first_bin * bl, last_bin * bl
    secs = list(sections) if sections is not None else _make_sections(rng, lo, hi, section_length_m)
    for s in secs:
        if s.type not in SUPERSTRUCTURE_TYPES:
            raise ValueError(f"sections: unknown superstructure type {s.type!r}")
    centres = (np.arange(first_bin, last_bin) + 0.5) * bl
    type_code = np.zeros(nb, dtype=np.int8)
    covered = np.zeros(nb, dtype=bool)
    for s in secs:
        m = (centres >= s.track_from_m) & (centres < s.track_to_m)
        type_code[m] = SUPERSTRUCTURE_TYPES.index(s.type)
        covered |= m
    if not covered.all():
        raise ValueError("sections: the sections do not cover the whole line")
    corr_bins = correlation_m / bl
    common = _smooth_noise(rng, nb, corr_bins)
    own = [_smooth_noise(rng, nb, corr_bins) for _ in range(2)]
    r = rail_correlation
    factor = np.stack([1.0 + variation_std * (r * common + np.sqrt(1 - r * r) * o) for o in own])
    np.clip(factor, 0.5, 1.5, out=factor)
    if anomalies is None:
        a_lo, a_hi = anomaly_range_m if anomaly_range_m is not None else (lo, hi)
        count = n_anomalies if n_anomalies is not None else max(1, round((hi - lo) / 3000.0))
        anomalies = _place_anomalies(rng, secs, a_lo, a_hi, count, anomaly_length_m)
    for an in anomalies:
        factor *= 1.0 + (an.factor - 1.0) * an.weight(centres)
    if surface is True:
        surface = generate_surface(lo, hi, rng)
    elif surface is False:
        surface = None
    elif surface is not None and not isinstance(surface, RailSurface):
        raise ValueError(f"surface: must be a bool or a RailSurface, got {type(surface).__name__}")
    return LineModel(
        first_bin=first_bin,
        type_code=type_code,
        factor=factor,
        sections=tuple(secs),
        anomalies=tuple(anomalies),
        amplitude_vref=amps,
        bin_length=bl,
        surface=surface,
    )
