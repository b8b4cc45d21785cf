"""Condition classes of fixed sections (200 m by default) from the speed-conditioned index.

Where places answer *where must we act*, section classes answer *how good is
the line*: as EN 13848-6 / CEN/TR 16513 class the track-geometry quality of
whole sections (typically 200 m) by the spread of the signal over them, each
section of a run gets

* ``level`` — the mean of its segments' index (ln units; 0 = the class's
  typical track at that speed, :mod:`app.analysis.stiffness.stiffness_index`),
* ``spread`` — the standard deviation of its segments' index,
* ``rms`` — ``√(level² + spread²)``, the root-mean-square departure of the
  section from its class's typical track: a section that is uniformly stiffer
  than its kind and one that varies a lot are both far from typical,

and a class ``A`` (best) … ``E`` from ``rms`` against four increasing
limits (:class:`SectionClassLimits`). A section needs ``min_fill`` of its
segments with data, else it has no class (``""``).

On rough rails the spread holds the rails' response at the sleeper spacing,
which changes from one 10 m segment to the next (each rail's own short-wave
roughness) and is no property of the support: given that scatter
(``rail_scatter``, :func:`~app.analysis.condition.run_places.class_scatter`:
0 on smooth rails) the section's spread is taken as the support's,
``√(spread² − mean rail_scatter²)`` (issue 33's line read "E: very poor"
over 1.6 of its 2.9 km, a rough rail over a sound support).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import check_positive

__all__ = ["SECTION_CLASSES", "DEFAULT_SECTION_LIMITS", "SectionClassLimits", "SectionClasses", "section_classes"]

#: Class labels, best first.
SECTION_CLASSES: tuple[str, ...] = ("A", "B", "C", "D", "E")


@dataclass(frozen=True)
class SectionClassLimits:
    """Upper limits of ``rms`` (ln units) of the classes A … D (above the last: E), strictly increasing."""

    a: float
    b: float
    c: float
    d: float

    def __post_init__(self) -> None:
        v = (self.a, self.b, self.c, self.d)
        if not all(np.isfinite(x) for x in v) or not 0 < self.a < self.b < self.c < self.d:
            raise ValueError(f"a, b, c, d: need 0 < a < b < c < d, got {v!r}")

    @property
    def limits(self) -> np.ndarray:
        """``[a, b, c, d]``."""
        return np.array([self.a, self.b, self.c, self.d])


#: Measured (``bench/bench_places.py``, healthy 200 m sections of the simulated histories: rms quantiles
#: p20 0.048, p50 0.066, p80 0.096, p99 0.147, largest 0.165): A is the best fifth of healthy track, B the
#: next three fifths, C the rest of healthy track, D beyond anything healthy measured, E a section whose
#: rms reaches a place's alert limit (0.25).
DEFAULT_SECTION_LIMITS = SectionClassLimits(0.05, 0.10, 0.17, 0.25)


@dataclass(frozen=True)
class SectionClasses:
    """Per section (arrays of equal length, ascending ``start_m``).

    Attributes
    ----------
    section : numpy.ndarray
        int64 section numbers (``floor(x / section_m)``).
    start_m, end_m : numpy.ndarray
        Extent, m.
    level, spread, rms : numpy.ndarray
        ln units (NaN without enough data); ``spread`` the support's (the rails' scatter taken out).
    rail_spread : numpy.ndarray
        The rails' scatter taken out of the spread, ln units (0: none given).
    n_segments : numpy.ndarray
        int64 segments with data.
    cls : numpy.ndarray
        Class label per section (object; ``""``: not enough data).
    """

    section: np.ndarray
    start_m: np.ndarray
    end_m: np.ndarray
    level: np.ndarray
    spread: np.ndarray
    rms: np.ndarray
    n_segments: np.ndarray
    cls: np.ndarray
    rail_spread: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.section.size)

    def length_by_class(self) -> dict[str, float]:
        """Length per class, m (``""``: sections without a class)."""
        length = self.end_m - self.start_m
        return {c: float(length[self.cls == c].sum()) for c in (*SECTION_CLASSES, "")}


def section_classes(
    seg: np.ndarray,
    index: np.ndarray,
    *,
    segment_m: float,
    limits: SectionClassLimits,
    section_m: float = 200.0,
    min_fill: float = 0.5,
    rail_scatter: np.ndarray | None = None,
) -> SectionClasses:
    """Class every section holding segments.

    Parameters
    ----------
    seg : numpy.ndarray
        Segment numbers (segment ``k`` covers ``[k · segment_m, (k + 1) · segment_m)``).
    index : numpy.ndarray
        Speed-conditioned index per segment (ln units; NaN: no data).
    segment_m : float
        Segment length, m (> 0, at most ``section_m``).
    limits : SectionClassLimits
    section_m : float
        Section length, m (> 0; a whole number of segments).
    min_fill : float
        Fraction of a section's segments that must have data, in (0, 1].
    rail_scatter : numpy.ndarray, optional
        The rails' scatter from segment to segment per segment, ln units (NaN: none known, taken as 0;
        :func:`~app.analysis.condition.run_places.class_scatter`): its mean square over a section's
        segments with data is taken out of the section's spread.

    Returns
    -------
    SectionClasses
        Sections holding at least one segment (with or without data), ascending.
    """
    check_positive(segment_m, "segment_m")
    check_positive(section_m, "section_m")
    ratio = section_m / segment_m
    if ratio < 1 or abs(ratio - round(ratio)) > 1e-9:
        raise ValueError(f"section_m: must be a whole multiple of segment_m ({segment_m}), got {section_m!r}")
    if not 0 < min_fill <= 1:
        raise ValueError(f"min_fill: must be in (0, 1], got {min_fill!r}")
    if not isinstance(limits, SectionClassLimits):
        raise TypeError("limits: must be a SectionClassLimits")
    s = np.asarray(seg)
    x = np.asarray(index, dtype=np.float64)
    if s.ndim != 1 or x.shape != s.shape:
        raise ValueError("seg, index: must be 1-D of equal length")
    rail = np.zeros(x.shape) if rail_scatter is None else np.asarray(rail_scatter, dtype=np.float64)
    if rail.shape != x.shape:
        raise ValueError(f"rail_scatter: must have one value per segment ({x.size}), got shape {rail.shape}")
    rail = np.where(np.isnan(rail), 0.0, rail)
    if np.any(rail < 0) or not np.all(np.isfinite(rail)):
        raise ValueError("rail_scatter: must be >= 0 and finite (NaN: none known)")
    s = s.astype(np.int64)
    per = int(round(ratio))
    sec = np.floor_divide(s, per)
    ids, inv = np.unique(sec, return_inverse=True)
    inv = inv.ravel()
    ok = np.isfinite(x)
    n = np.bincount(inv, weights=ok.astype(float), minlength=ids.size)
    sx = np.bincount(inv, weights=np.where(ok, x, 0.0), minlength=ids.size)
    enough = n >= max(min_fill * per, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        level = sx / n
        dev = np.where(ok, x - level[inv], 0.0)
        var = np.bincount(inv, weights=dev * dev, minlength=ids.size) / np.maximum(n - 1, 1)
    rail_ms = np.bincount(inv, weights=np.where(ok, rail * rail, 0.0), minlength=ids.size) / np.maximum(n, 1)
    spread = np.where(n >= 2, np.sqrt(np.maximum(var - rail_ms, 0.0)), 0.0)
    level = np.where(enough, level, np.nan)
    spread = np.where(enough, spread, np.nan)
    rail_spread = np.where(enough, np.sqrt(rail_ms), np.nan)
    rms = np.sqrt(level**2 + spread**2)
    # a class holds its upper limit (a section exactly at it is not pushed over by rounding of the mean)
    k = np.searchsorted(limits.limits, np.nan_to_num(rms, nan=0.0) - 1e-12, side="left")
    labels = np.array(SECTION_CLASSES, dtype=object)[np.minimum(k, len(SECTION_CLASSES) - 1)]
    cls = np.where(enough, labels, "").astype(object)
    return SectionClasses(section=ids.astype(np.int64), start_m=ids * section_m, end_m=(ids + 1) * section_m,
                          level=level, spread=spread, rms=rms, n_segments=n.astype(np.int64), cls=cls,
                          rail_spread=rail_spread)
