"""The condition index of the segment condition store: the log of the raw amplitude, ``ln(A / 1 m/s²)``.

Two indexes live in trackvkf, with distinct names everywhere:

- the **condition index** (this module, provenance name :data:`LOG_AMPLITUDE_INDEX`,
  ``"ln_amplitude"``): what the segment condition store keeps for every 10 m / 100 m segment
  and what its change tests, heat maps, trends, hotspots and maintenance effects compare. It
  is not speed-conditioned itself: values are compared only at matched speed
  (:mod:`app.analysis.speed_match`; the change tests also level each run against its
  surroundings and estimate a speed exponent within segments,
  :mod:`app.analysis.condition.change`), so rows stored years apart stay comparable;
- the **stiffness index** ``ln(A / A_ref(class, v))`` (:mod:`app.analysis.stiffness.stiffness_index`):
  the amplitude against the line's current reference curves, answered with the profiles
  (``index=true``) and the analytics; it moves when the curves are re-estimated, which is why
  the store does not keep it.

**Its stated uncertainty** (:func:`log_amplitude_segment_sd`): a segment's index is the mean of
its bins' ``ln A``. Its 1-σ is that of the segment's mean amplitude, from the profile's stated
1-σ of every bin (``sleeper_amp_sd``, of which ``sleeper_amp_sd_shared`` is shared along the floor
window) through :func:`app.analysis.uncertainty.segment_sd` (the one rule that aggregates bins to
a segment with their along-track correlation), over the segment's mean amplitude: the delta
method ``σ(ln Ā) ≈ σ(Ā) / Ā``, at the segment, not per bin — on rough rail single bins are often
near 0 (the two-rail estimate is clipped there) and ``sd / A`` of such a bin says nothing of the
segment. Where the profile states no 1-σ (old runs, a profile without the columns) the segment's
is NaN: none known — never 0.

:mod:`app.condition.index` is the one place that decides which index the store holds.
"""

from __future__ import annotations

import numpy as np

from app.analysis.uncertainty import segment_sd

__all__ = ["LOG_AMPLITUDE_INDEX", "log_amplitude_index", "log_amplitude_segment_sd"]

#: Name of the condition index in the provenance of stored rows (``meta["condition"]["condition_index"]``,
#: the heat map's ``condition_index``).
LOG_AMPLITUDE_INDEX = "ln_amplitude"


def log_amplitude_index(amplitude: np.ndarray) -> np.ndarray:
    """``ln(A / 1 m/s²)`` per bin (NaN where ``A`` is not positive).

    Parameters
    ----------
    amplitude : numpy.ndarray
        Sleeper-passage amplitude, m/s².

    Returns
    -------
    numpy.ndarray
        The index, natural log units.
    """
    a = np.asarray(amplitude, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(a > 0, np.log(np.where(a > 0, a, 1.0)), np.nan)


def log_amplitude_segment_sd(
    position_m: np.ndarray,
    amplitude: np.ndarray,
    sd: np.ndarray | None,
    shared: np.ndarray | None = None,
    *,
    segment_m: float,
    bin_length_m: float = 0.25,
    resolution_m: float = 3.0,
    filter_order: int = 2,
) -> tuple[np.ndarray, np.ndarray]:
    """Stated 1-σ of each segment's condition index (mean of its bins' ``ln A``), natural log units.

    Parameters
    ----------
    position_m : numpy.ndarray
        (n,) bin centres on the (aligned) km axis, m; segment ``floor(position_m / segment_m)``.
    amplitude : numpy.ndarray
        (n,) sleeper-passage amplitude, m/s² (NaN or ≤ 0: the bin is not in the segment's index).
    sd : numpy.ndarray or None
        (n,) 1-σ of each bin's amplitude, m/s² (``sleeper_amp_sd``; NaN: none stated). None: no bin
        states one.
    shared : numpy.ndarray, optional
        (n,) the part of ``sd`` shared along the floor window (``sleeper_amp_sd_shared``), m/s².
    segment_m : float
        Segment length, m (a multiple of ``bin_length_m``).
    bin_length_m : float, optional
        m (default 0.25).
    resolution_m, filter_order : optional
        The track orders' resolution (m) and q the profile was processed with (defaults 3 m, 2).

    Returns
    -------
    segments : numpy.ndarray
        int64 segment numbers with at least one bin with a positive amplitude and a finite ``sd``.
    index_sd : numpy.ndarray
        1-σ of the segment's index: :func:`~app.analysis.uncertainty.segment_sd` of ``sd`` (and
        ``shared``) over those bins, divided by their mean amplitude (delta method).

    Raises
    ------
    ValueError
        If the arrays' shapes differ or a length is not > 0.
    """
    x = np.asarray(position_m, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"position_m: must be 1-D, got shape {x.shape}")
    a = np.asarray(amplitude, dtype=np.float64)
    if a.shape != x.shape:
        raise ValueError(f"amplitude: must have the shape of position_m {x.shape}, got {a.shape}")
    if not (np.isfinite(bin_length_m) and bin_length_m > 0):
        raise ValueError(f"bin_length_m: must be > 0 m, got {bin_length_m!r}")
    if sd is None:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    s = np.asarray(sd, dtype=np.float64)
    if s.shape != x.shape:
        raise ValueError(f"sd: must have the shape of position_m {x.shape}, got {s.shape}")
    sh = None
    if shared is not None:
        sh = np.asarray(shared, dtype=np.float64)
        if sh.shape != x.shape:
            raise ValueError(f"shared: must have the shape of position_m {x.shape}, got {sh.shape}")
    ok = np.isfinite(x) & np.isfinite(a) & (a > 0) & np.isfinite(s) & (s >= 0)
    if not ok.any():
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    # position_m on a shifted axis: bins keep their spacing, the segment is that of the bin's start
    bins = np.floor(x[ok] / bin_length_m).astype(np.int64)
    segments, sd_mean = segment_sd(bins, s[ok], segment_m, bin_length_m, resolution_m, filter_order,
                                   shared=None if sh is None else sh[ok])
    k = int(round(segment_m / bin_length_m))
    seg_of = np.floor_divide(bins, k)
    j = np.searchsorted(segments, seg_of)
    mean = np.bincount(j, weights=a[ok], minlength=segments.size) / np.bincount(j, minlength=segments.size)
    return segments, sd_mean / mean
