"""Places: adjacent segments beyond a threshold merged into one exception with its extent and peak.

An engineer acts on a *place* — "km 12.340–12.370, +24 %, peak at 12.356" — not on
the three 10 m rows it covers. As in the automated geometry exception reports
(consecutive exceedances make one exception with its length and peak), the
segments of a run whose evidence passes its threshold are merged along the km
axis:

* two exceeding segments of the **same direction** belong to one place when the
  gap between them (segments not exceeding, or without data) is at most
  ``gap_m``; a change of direction always starts a new place;
* a place's **extent** is ``[first segment start, last segment end)``, its
  **peak** the segment with the largest ``direction · value`` (its value and its
  centre km);
* its **centre** is the centroid of ``max(direction · value, 0)`` over its
  segments and the neighbouring segment on either side (a 20 m change that
  straddles three 10 m segments, covering 5 / 10 / 5 m of them, has its centroid
  at the change's centre, not at the middle segment's);
* its **evidence** and **wheels** are the union (bitwise or) of those of its
  exceeding segments (:data:`EVIDENCE_BITS`; wheel bits as the caller numbers them).

Everything is in metres on the run's aligned km axis; ``value`` is whatever the
caller grades (the speed-conditioned index, a change against the history, …).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import check_positive

__all__ = [
    "EVIDENCE_ANOMALY",
    "EVIDENCE_STEP",
    "EVIDENCE_TREND",
    "EVIDENCE_BITS",
    "evidence_names",
    "PlaceTable",
    "merge_places",
]

#: Evidence bits: the place stands out against its superstructure class at its speed.
EVIDENCE_ANOMALY = 1
#: The step test against the place's own history fired.
EVIDENCE_STEP = 2
#: The trend test fired.
EVIDENCE_TREND = 4
#: Name of each evidence bit.
EVIDENCE_BITS: dict[int, str] = {EVIDENCE_ANOMALY: "anomaly", EVIDENCE_STEP: "step", EVIDENCE_TREND: "trend"}


def evidence_names(bits: int) -> list[str]:
    """Names of the evidence bits set in ``bits`` (in :data:`EVIDENCE_BITS` order)."""
    return [name for bit, name in EVIDENCE_BITS.items() if int(bits) & bit]


@dataclass(frozen=True)
class PlaceTable:
    """Places of one run (arrays of equal length, ascending ``start_m``).

    Attributes
    ----------
    start_m, end_m : numpy.ndarray
        Extent on the km axis, m.
    centre_m : numpy.ndarray
        Centroid of the excess (module docstring), m.
    peak_m : numpy.ndarray
        Centre of the peak segment, m.
    peak : numpy.ndarray
        ``value`` of the peak segment (signed).
    direction : numpy.ndarray
        int64 +1 (value above) / −1 (below).
    evidence : numpy.ndarray
        int64 union of the segments' evidence bits.
    wheels : numpy.ndarray
        int64 union of the segments' wheel bits.
    n_segments : numpy.ndarray
        int64 exceeding segments merged.
    first, last : numpy.ndarray
        int64 positions (into the input arrays) of the first and last exceeding segment.
    """

    start_m: np.ndarray
    end_m: np.ndarray
    centre_m: np.ndarray
    peak_m: np.ndarray
    peak: np.ndarray
    direction: np.ndarray
    evidence: np.ndarray
    wheels: np.ndarray
    n_segments: np.ndarray
    first: np.ndarray
    last: np.ndarray

    def __len__(self) -> int:
        return int(self.start_m.size)

    @property
    def length_m(self) -> np.ndarray:
        """Length of each place, m."""
        return self.end_m - self.start_m


def _vector(values: object, n: int, name: str, dtype: type) -> np.ndarray:
    a = np.asarray(values, dtype=dtype)
    if a.shape != (n,):
        raise ValueError(f"{name}: must be 1-D with one value per segment ({n}), got shape {a.shape}")
    return a


def merge_places(
    seg: np.ndarray,
    value: np.ndarray,
    exceed: np.ndarray,
    *,
    segment_m: float,
    gap_m: float = 10.0,
    evidence: np.ndarray | None = None,
    wheels: np.ndarray | None = None,
) -> PlaceTable:
    """Merge exceeding segments into places.

    Parameters
    ----------
    seg : numpy.ndarray
        Segment numbers (int; segment ``k`` covers ``[k · segment_m, (k + 1) · segment_m)``), strictly ascending.
    value : numpy.ndarray
        Graded quantity per segment (signed; its sign is the direction; NaN: no data).
    exceed : numpy.ndarray
        bool per segment: the segment passes its threshold (ignored where ``value`` is NaN or 0).
    segment_m : float
        Segment length, m (> 0).
    gap_m : float
        Largest gap between two exceeding segments of one place, m (≥ 0; 0: only touching segments merge).
    evidence, wheels : numpy.ndarray, optional
        int bits per segment (default 0).

    Returns
    -------
    PlaceTable
    """
    check_positive(segment_m, "segment_m")
    if not (np.isfinite(gap_m) and gap_m >= 0):
        raise ValueError(f"gap_m: must be a finite number >= 0, got {gap_m!r}")
    s = np.asarray(seg)
    if s.ndim != 1:
        raise ValueError(f"seg: must be 1-D, got shape {s.shape}")
    if s.size and not np.issubdtype(s.dtype, np.integer):
        if not np.all(np.isfinite(s)) or np.any(s != np.round(s)):
            raise ValueError("seg: must hold integer segment numbers")
    s = s.astype(np.int64)
    n = s.size
    if n > 1 and np.any(np.diff(s) <= 0):
        raise ValueError("seg: must be strictly ascending")
    v = _vector(value, n, "value", np.float64)
    ex = _vector(exceed, n, "exceed", bool)
    ev = np.zeros(n, np.int64) if evidence is None else _vector(evidence, n, "evidence", np.int64)
    wh = np.zeros(n, np.int64) if wheels is None else _vector(wheels, n, "wheels", np.int64)
    sign = np.sign(np.nan_to_num(v)).astype(np.int64)
    hot = np.flatnonzero(ex & (sign != 0))
    if hot.size == 0:
        e = np.zeros(0)
        ei = np.zeros(0, np.int64)
        return PlaceTable(e, e, e, e, e, ei, ei, ei, ei, ei, ei)
    max_gap_segs = int(np.floor(gap_m / segment_m + 1e-9))
    # a new place starts where the direction changes or the gap is too long
    gaps = s[hot[1:]] - s[hot[:-1]] - 1
    new = np.r_[True, (sign[hot[1:]] != sign[hot[:-1]]) | (gaps > max_gap_segs)]
    starts = np.flatnonzero(new)
    ends = np.r_[starts[1:], hot.size] - 1
    k = starts.size
    out = {name: np.zeros(k) for name in ("start_m", "end_m", "centre_m", "peak_m", "peak")}
    ints = {name: np.zeros(k, np.int64) for name in ("direction", "evidence", "wheels", "n_segments", "first", "last")}
    for p in range(k):
        rows = hot[starts[p]: ends[p] + 1]
        d = int(sign[rows[0]])
        i0, i1 = int(rows[0]), int(rows[-1])
        j = rows[np.argmax(d * v[rows])]
        # the centroid over the place's segments and a touching neighbour on either side
        lo, hi = i0, i1
        if lo > 0 and s[lo - 1] == s[lo] - 1:
            lo -= 1
        if hi < n - 1 and s[hi + 1] == s[hi] + 1:
            hi += 1
        span = np.arange(lo, hi + 1)
        w = np.clip(d * np.nan_to_num(v[span]), 0.0, None)
        centres = (s[span] + 0.5) * segment_m
        out["start_m"][p] = s[i0] * segment_m
        out["end_m"][p] = (s[i1] + 1) * segment_m
        out["centre_m"][p] = float(np.sum(w * centres) / np.sum(w)) if np.sum(w) > 0 else float(centres.mean())
        out["peak_m"][p] = (s[j] + 0.5) * segment_m
        out["peak"][p] = v[j]
        ints["direction"][p] = d
        ints["evidence"][p] = int(np.bitwise_or.reduce(ev[rows]))
        ints["wheels"][p] = int(np.bitwise_or.reduce(wh[rows]))
        ints["n_segments"][p] = rows.size
        ints["first"][p], ints["last"][p] = i0, i1
    return PlaceTable(**out, **ints)
