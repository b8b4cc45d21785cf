"""Amplitude per superstructure type (the paper's clusters) and segments departing from it.

Each bin is assigned the superstructure section that holds its centre. Per
type, the distribution of the bin amplitudes is summarised; the sections are
cut into segments (default 100 m) and each segment's median log-amplitude is
compared with the segments of the same type: a robust z-score (median and
1.4826 MAD of the type's segment medians) beyond a threshold flags the segment
as a candidate for inspection.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import check_positive, paired_1d
from app.analysis.robust import mad_sd

__all__ = ["TypeDistribution", "SegmentFlag", "assign_sections", "section_classes", "type_distributions",
           "flag_segments", "OUTLIER_SEGMENT_M"]

#: Default segment length of the outlying-segment search (:func:`flag_segments`), m.
OUTLIER_SEGMENT_M = 100.0


@dataclass(frozen=True)
class TypeDistribution:
    """Amplitude distribution (m/s²) of the bins of one superstructure type."""

    type: str
    n_bins: int
    mean: float
    median: float
    q05: float
    q25: float
    q75: float
    q95: float


@dataclass(frozen=True)
class SegmentFlag:
    """One segment of a section: its median amplitude and departure from its type."""

    section: int
    type: str
    start_m: float
    end_m: float
    n_bins: int
    median: float
    z: float
    flagged: bool


def assign_sections(position_m: np.ndarray, start_m: np.ndarray, end_m: np.ndarray) -> np.ndarray:
    """Index of the section ``[start_m, end_m)`` holding each position, -1 if none.

    Where sections overlap, the one starting last wins.
    """
    x = np.asarray(position_m, dtype=np.float64)
    a, b = paired_1d(start_m, end_m, "start_m, end_m")
    out = np.full(x.shape, -1, dtype=np.int64)
    for i in np.argsort(a, kind="stable"):
        out[(x >= a[i]) & (x < b[i])] = i
    return out


def section_classes(
    position_m: np.ndarray,
    start_m: np.ndarray,
    end_m: np.ndarray,
    types: np.ndarray,
    *,
    boundary_margin_m: float = 0.0,
) -> np.ndarray:
    """Class label per position: the type of the section holding it, ``""`` outside any.

    Positions within ``boundary_margin_m`` of a place where the label changes
    (a section of another type, or the end of the sections) get ``None``: the
    filtered amplitude there mixes both sides (the VKF resolves the sleeper
    order over tens of metres), so it belongs to neither class.

    Parameters
    ----------
    position_m : numpy.ndarray
        Positions (bin centres), m on the km axis.
    start_m, end_m : numpy.ndarray
        Section extents ``[start_m, end_m)``, m.
    types : numpy.ndarray
        Type of each section.
    boundary_margin_m : float
        Half-width of the zone left without a class around each change, m (>= 0).
    """
    x = np.asarray(position_m, dtype=np.float64)
    if not boundary_margin_m >= 0:
        raise ValueError(f"boundary_margin_m: must be >= 0, got {boundary_margin_m!r}")
    kinds = np.asarray(types, dtype=object)
    idx = assign_sections(x, start_m, end_m) if kinds.size else np.full(x.shape, -1)
    out = np.where(idx >= 0, kinds[np.maximum(idx, 0)] if kinds.size else "", "").astype(object)
    if boundary_margin_m > 0 and kinds.size:
        edges = np.unique(np.r_[np.asarray(start_m, dtype=np.float64), np.asarray(end_m, dtype=np.float64)])
        probe = np.r_[edges - 1e-6, edges + 1e-6]
        pidx = assign_sections(probe, start_m, end_m)
        plab = np.where(pidx >= 0, kinds[np.maximum(pidx, 0)], "").astype(str)
        change = edges[plab[: edges.size] != plab[edges.size:]]
        if change.size:
            j = np.searchsorted(change, x)
            left = change[np.clip(j - 1, 0, change.size - 1)]
            right = change[np.clip(j, 0, change.size - 1)]
            out[np.minimum(np.abs(x - left), np.abs(x - right)) < boundary_margin_m] = None
    return out


def type_distributions(amplitude: np.ndarray, types: np.ndarray) -> list[TypeDistribution]:
    """Distribution of ``amplitude`` (m/s², finite) per type label (empty label = no section)."""
    amplitude = np.asarray(amplitude, dtype=np.float64)
    types = np.asarray(types, dtype=object)
    if types.shape != amplitude.shape:
        raise ValueError("amplitude, types: must have equal shapes")
    out = []
    for t in sorted({str(t) for t in types if t}):
        v = amplitude[types == t]
        q = np.percentile(v, [5, 25, 50, 75, 95])
        out.append(TypeDistribution(t, int(v.size), float(v.mean()), float(q[2]), float(q[0]),
                                    float(q[1]), float(q[3]), float(q[4])))
    return out


def flag_segments(
    position_m: np.ndarray,
    amplitude: np.ndarray,
    section: np.ndarray,
    section_types: list[str],
    *,
    segment_m: float = OUTLIER_SEGMENT_M,
    bin_length_m: float = 0.25,
    z_threshold: float = 3.5,
    min_coverage: float = 0.5,
    min_segments: int = 5,
) -> list[SegmentFlag]:
    """Segments of each section and their robust z-score within their type.

    Parameters
    ----------
    position_m : numpy.ndarray
        Bin centres, m on the km axis.
    amplitude : numpy.ndarray
        Amplitude per bin, m/s² (> 0, finite).
    section : numpy.ndarray
        Section index per bin (:func:`assign_sections`; -1 = none).
    section_types : list of str
        Type of each section.
    segment_m : float
        Segment length, m (> 0); segments follow the grid ``floor(x / segment_m)``
        cut at section ends.
    bin_length_m : float
        Bin length, m.
    z_threshold : float
        ``|z|`` beyond which a segment is flagged (> 0).
    min_coverage : float
        Fraction of a full segment's bins a segment needs to be scored.
    min_segments : int
        Fewer scored segments of a type give no z-scores (NaN, never flagged).
    """
    x = np.asarray(position_m, dtype=np.float64)
    amp = np.asarray(amplitude, dtype=np.float64)
    sec = np.asarray(section, dtype=np.int64)
    if not (x.shape == amp.shape == sec.shape):
        raise ValueError("position_m, amplitude, section: must have equal shapes")
    check_positive(segment_m, "segment_m")
    check_positive(z_threshold, "z_threshold")
    if np.any(~(amp[sec >= 0] > 0)):
        raise ValueError("amplitude: must be > 0 m/s²")
    need = min_coverage * segment_m / bin_length_m
    seg = np.floor(x / segment_m).astype(np.int64)
    rows = []
    keep = sec >= 0
    keys = np.stack([sec[keep], seg[keep]], axis=1)
    logs, xs = np.log(amp[keep]), x[keep]
    if keys.size:
        uniq, inv = np.unique(keys, axis=0, return_inverse=True)
        inv = inv.ravel()
        for j, (s, _g) in enumerate(uniq):
            m = inv == j
            if m.sum() < need:
                continue
            rows.append((int(s), section_types[int(s)], float(xs[m].min() - bin_length_m / 2),
                         float(xs[m].max() + bin_length_m / 2), int(m.sum()), float(np.median(logs[m]))))
    out = []
    for t in sorted({r[1] for r in rows}):
        vals = np.array([r[5] for r in rows if r[1] == t])
        med = float(np.median(vals))
        scale = mad_sd(vals, center=med)
        for r in (r for r in rows if r[1] == t):
            z = (r[5] - med) / scale if vals.size >= min_segments and scale > 0 else float("nan")
            out.append(SegmentFlag(r[0], t, r[2], r[3], r[4], float(np.exp(r[5])), float(z),
                                   bool(np.isfinite(z) and abs(z) > z_threshold)))
    return sorted(out, key=lambda f: f.start_m)
