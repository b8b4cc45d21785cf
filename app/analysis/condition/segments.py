"""Segment statistics of one run and wheel: 25 cm bins → 10 m / 100 m condition rows.

A segment is ``[seg · segment_m, (seg + 1) · segment_m)`` on the (aligned) km
axis in metres, ``seg = floor(position_m / segment_m)``. Of the bins whose
centre lies in it, the *valid* ones (finite positive amplitude, finite speed
and index) give:

* ``amp_mean``, ``amp_p95``: mean and 95th percentile (linear interpolation) of
  the sleeper-passage amplitude, m/s²;
* ``speed_mean``: mean speed, m/s;
* ``index``: mean of the bins' condition index (natural log units);
* ``index_sd``: its stated 1-σ where the caller knows it (``index_sd`` per segment,
  :func:`app.condition.index.store_index_sd` decides it for the store), else NaN: none known.
  The spread of the bins within a segment is not its uncertainty (a soft spot inside a
  segment spreads its bins; a smooth segment of a rough rail does not), so it is not used.

Segments with fewer valid bins than ``min_valid_fraction`` of their length are
left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import check_positive

__all__ = ["SEGMENT_LENGTHS_M", "OVERVIEW_SEGMENT_M", "FINE_SEGMENT_M", "SegmentStats", "segment_stats"]

#: Segment lengths of the condition store, m.
SEGMENT_LENGTHS_M: tuple[float, ...] = (10.0, 100.0)
#: Segment length of a run's overview rows (the line's heat map: mean over the wheels), m.
OVERVIEW_SEGMENT_M: float = SEGMENT_LENGTHS_M[-1]
#: The finest segment length of the store (a segment's trend, the work list), m.
FINE_SEGMENT_M: float = SEGMENT_LENGTHS_M[0]


@dataclass(frozen=True)
class SegmentStats:
    """Per-segment statistics of one run and wheel (arrays of equal length, ascending ``seg``).

    Attributes
    ----------
    seg : numpy.ndarray
        int64 segment numbers, ``floor(position_m / segment_m)``.
    n_valid : numpy.ndarray
        int64 number of valid bins.
    amp_mean, amp_p95 : numpy.ndarray
        Mean and 95th percentile of the amplitude, m/s².
    speed_mean : numpy.ndarray
        Mean speed, m/s.
    index, index_sd : numpy.ndarray
        Mean condition index and its stated 1-σ (log units; NaN: none known).
    """

    seg: np.ndarray
    n_valid: np.ndarray
    amp_mean: np.ndarray
    amp_p95: np.ndarray
    speed_mean: np.ndarray
    index: np.ndarray
    index_sd: np.ndarray

    def __len__(self) -> int:
        return int(self.seg.size)


def _as_1d(values: object, n: int, name: str) -> np.ndarray:
    out = np.asarray(values, dtype=np.float64)
    if out.shape != (n,):
        raise ValueError(f"{name}: must be 1-D with the length of position_m ({n}), got shape {out.shape}")
    return out


def segment_stats(
    position_m: np.ndarray,
    amplitude: np.ndarray,
    speed_mps: np.ndarray,
    index: np.ndarray,
    *,
    segment_m: float,
    bin_length_m: float = 0.25,
    min_valid_fraction: float = 0.5,
) -> SegmentStats:
    """Aggregate one wheel's bins into segments.

    Parameters
    ----------
    position_m : numpy.ndarray
        Bin centres on the (aligned) km axis, m.
    amplitude : numpy.ndarray
        Sleeper-passage amplitude per bin, m/s² (NaN or ≤ 0: not valid).
    speed_mps : numpy.ndarray
        Speed per bin, m/s (NaN: not valid).
    index : numpy.ndarray
        Condition index per bin (log units; NaN: not valid).
    segment_m : float
        Segment length, m (> 0).
    bin_length_m : float
        Bin length, m (> 0).
    min_valid_fraction : float
        Segments with fewer valid bins than this fraction of
        ``segment_m / bin_length_m`` are left out, in [0, 1].

    Returns
    -------
    SegmentStats
        ``index_sd`` NaN (the caller states it: :func:`app.condition.index.store_index_sd`).
    """
    check_positive(segment_m, "segment_m")
    check_positive(bin_length_m, "bin_length_m")
    if not 0.0 <= min_valid_fraction <= 1.0:
        raise ValueError(f"min_valid_fraction: must be in [0, 1], got {min_valid_fraction!r}")
    x = np.asarray(position_m, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError("position_m: must be 1-D")
    n = x.size
    amp = _as_1d(amplitude, n, "amplitude")
    v = _as_1d(speed_mps, n, "speed_mps")
    idx = _as_1d(index, n, "index")
    ok = np.isfinite(x) & np.isfinite(amp) & (amp > 0) & np.isfinite(v) & np.isfinite(idx)
    seg_all = np.floor(x[ok] / segment_m).astype(np.int64)
    amp, v, idx = amp[ok], v[ok], idx[ok]
    order = np.lexsort((amp, seg_all))  # by segment, then amplitude (for the percentile)
    seg_sorted = seg_all[order]
    segs, start, counts = np.unique(seg_sorted, return_index=True, return_counts=True)
    need = min_valid_fraction * segment_m / bin_length_m
    keep = counts >= max(need, 1.0)
    group = np.repeat(np.arange(segs.size), counts)

    def mean_of(values: np.ndarray) -> np.ndarray:
        return np.bincount(group, weights=values[order], minlength=segs.size) / np.maximum(counts, 1)

    amp_mean = mean_of(amp)
    speed_mean = mean_of(v)
    idx_mean = mean_of(idx)
    # 95th percentile with linear interpolation between order statistics (numpy's default)
    pos = 0.95 * (counts - 1)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, counts - 1)
    amp_sorted = amp[order]
    frac = pos - lo
    p95 = amp_sorted[start + lo] * (1 - frac) + amp_sorted[start + hi] * frac
    return SegmentStats(
        seg=segs[keep],
        n_valid=counts[keep].astype(np.int64),
        amp_mean=amp_mean[keep],
        amp_p95=p95[keep],
        speed_mean=speed_mean[keep],
        index=idx_mean[keep],
        index_sd=np.full(int(keep.sum()), np.nan),
    )
