"""Run alignment by cross-correlating amplitude signatures, and per-segment repeatability.

Odometry drifts, so the km axes of two runs over the same track differ by a
shift. The *signature* of a run is its log sleeper-passage amplitude on the
25 cm grid with its moving mean (``detrend_m``) removed, so that speed and
superstructure level do not dominate. The shift maximises the normalised
cross-correlation (Pearson r over the overlap, gaps allowed) within
``±max_shift_m``, refined to a fraction of a bin by a parabola through the
peak.

Sign: ``shift_m`` is added to the run's positions to align it with the
reference (``km_aligned = km + shift_m / 1000``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import check_positive
from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE, speeds_matched
from app.analysis.stiffness.reference_curve.smoother import group_median

__all__ = ["Alignment", "signature", "align_runs", "SegmentTable", "segment_table", "DEFAULT_SEGMENT_M",
           "DEFAULT_MAX_SHIFT_M", "DEFAULT_DETREND_M"]

#: Default segment length of the runs-by-segment comparison (the line view's heat map), m.
DEFAULT_SEGMENT_M = 100.0
#: Largest shift an alignment searches by default, m (odometry drift between runs stays within it).
DEFAULT_MAX_SHIFT_M = 50.0
#: Moving-mean length removed from the alignment signatures by default, m.
DEFAULT_DETREND_M = 50.0


@dataclass(frozen=True)
class Alignment:
    """Shift of a run relative to a reference run.

    Attributes
    ----------
    shift_m : float
        Add to the run's positions (m) to align it with the reference.
    confidence : float
        Peak correlation minus the best correlation outside the main lobe, in
        [0, 1]: near 0 = ambiguous, near 1 = one clear match.
    peak_r : float
        Pearson r of the signatures at the best shift.
    second_r : float
        Best r outside the main lobe (NaN when the lobe fills the search range).
    overlap_m : float
        Length of the overlap with valid data in both runs at the best shift, m.
    lags_m : numpy.ndarray
        Shifts searched, m.
    correlation : numpy.ndarray
        r at each shift (NaN where the overlap is too short).
    """

    shift_m: float
    confidence: float
    peak_r: float
    second_r: float
    overlap_m: float
    lags_m: np.ndarray
    correlation: np.ndarray


def signature(bins: np.ndarray, amplitude: np.ndarray, *, bin_length_m: float = 0.25,
              detrend_m: float = DEFAULT_DETREND_M) -> tuple[int, np.ndarray]:
    """Detrended log amplitude on a contiguous grid.

    Parameters
    ----------
    bins : numpy.ndarray
        Bin indices (``floor(x / bin_length_m)``), unique.
    amplitude : numpy.ndarray
        Amplitude per bin, m/s² (non-positive or NaN = missing).
    bin_length_m, detrend_m : float
        Bin length and the length of the moving mean removed, m.

    Returns
    -------
    first_bin : int
        Bin index of the grid's first cell.
    values : numpy.ndarray
        Signature per cell (NaN where missing).
    """
    bins = np.asarray(bins, dtype=np.int64)
    amp = np.asarray(amplitude, dtype=np.float64)
    if bins.shape != amp.shape or bins.ndim != 1 or bins.size == 0:
        raise ValueError("bins, amplitude: must be non-empty, 1-D, of equal length")
    if not (bin_length_m > 0 and detrend_m > 0):
        raise ValueError("bin_length_m, detrend_m: must be > 0")
    b0 = int(bins.min())
    grid = np.full(int(bins.max()) - b0 + 1, np.nan)
    ok = np.isfinite(amp) & (amp > 0)
    grid[bins[ok] - b0] = np.log(amp[ok])
    valid = np.isfinite(grid)
    w = max(int(round(detrend_m / bin_length_m)), 1)
    from scipy import ndimage  # here: the settings name this module's constants (light import)

    num = ndimage.uniform_filter1d(np.where(valid, grid, 0.0), w, mode="constant")
    den = ndimage.uniform_filter1d(valid.astype(float), w, mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        trend = num / den
    return b0, np.where(valid, grid - trend, np.nan)


def _xcorr(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    from scipy import signal

    return signal.correlate(b, a, mode="full", method="fft")


def align_runs(
    ref_bins: np.ndarray,
    ref_amplitude: np.ndarray,
    bins: np.ndarray,
    amplitude: np.ndarray,
    *,
    bin_length_m: float = 0.25,
    max_shift_m: float = DEFAULT_MAX_SHIFT_M,
    detrend_m: float = DEFAULT_DETREND_M,
    min_overlap_m: float = 100.0,
) -> Alignment:
    """Shift that aligns a run's amplitude profile with a reference run's.

    Parameters
    ----------
    ref_bins, ref_amplitude : numpy.ndarray
        Reference run: bin indices and amplitude (m/s²).
    bins, amplitude : numpy.ndarray
        The run to align.
    bin_length_m : float
        Bin length, m.
    max_shift_m : float
        Largest shift searched, m (> 0).
    detrend_m : float
        Moving-mean length removed from the signatures, m.
    min_overlap_m : float
        Shorter overlaps are not scored, m.

    Returns
    -------
    Alignment
        ``shift_m`` NaN and confidence 0 when no shift has enough overlap.
    """
    check_positive(max_shift_m, "max_shift_m")
    ra0, ra = signature(ref_bins, ref_amplitude, bin_length_m=bin_length_m, detrend_m=detrend_m)
    rb0, rb = signature(bins, amplitude, bin_length_m=bin_length_m, detrend_m=detrend_m)
    k_max = int(np.ceil(max_shift_m / bin_length_m))
    # common grid starting at the lower first bin
    g0 = min(ra0, rb0)
    n = max(ra0 + ra.size, rb0 + rb.size) - g0
    a = np.full(n, np.nan)
    b = np.full(n, np.nan)
    a[ra0 - g0: ra0 - g0 + ra.size] = ra
    b[rb0 - g0: rb0 - g0 + rb.size] = rb
    ma, mb = np.isfinite(a).astype(float), np.isfinite(b).astype(float)
    a0, b0 = np.nan_to_num(a), np.nan_to_num(b)
    # full correlation index n-1 is lag 0; lag k pairs a[i] with b[i + k]
    cnt = _xcorr(ma, mb)
    sa, sb = _xcorr(a0, mb), _xcorr(ma, b0)
    saa, sbb = _xcorr(a0 * a0, mb), _xcorr(ma, b0 * b0)
    sab = _xcorr(a0, b0)
    mid = n - 1
    lags = np.arange(-k_max, k_max + 1)
    idx = mid + lags
    inside = (idx >= 0) & (idx < 2 * n - 1)
    r = np.full(lags.size, np.nan)
    overlap = np.zeros(lags.size)
    c = np.round(cnt[idx[inside]])
    with np.errstate(invalid="ignore", divide="ignore"):
        cov = sab[idx[inside]] - sa[idx[inside]] * sb[idx[inside]] / c
        va = saa[idx[inside]] - sa[idx[inside]] ** 2 / c
        vb = sbb[idx[inside]] - sb[idx[inside]] ** 2 / c
        rr = cov / np.sqrt(va * vb)
    enough = c * bin_length_m >= min_overlap_m
    r[inside] = np.where(enough & (va > 0) & (vb > 0), rr, np.nan)
    overlap[inside] = c * bin_length_m
    lags_m = lags * bin_length_m
    if not np.any(np.isfinite(r)):
        return Alignment(float("nan"), 0.0, float("nan"), float("nan"), 0.0, lags_m, r)
    p = int(np.nanargmax(r))
    frac = 0.0
    if 0 < p < r.size - 1 and np.isfinite(r[p - 1]) and np.isfinite(r[p + 1]):
        den = r[p - 1] - 2 * r[p] + r[p + 1]
        if den < 0:
            frac = float(np.clip(0.5 * (r[p - 1] - r[p + 1]) / den, -0.5, 0.5))
    lag_bins = lags[p] + frac
    # main lobe: contiguous run around the peak where r > peak / 2
    half = r[p] / 2
    lo = p
    while lo > 0 and np.isfinite(r[lo - 1]) and r[lo - 1] > half:
        lo -= 1
    hi = p
    while hi < r.size - 1 and np.isfinite(r[hi + 1]) and r[hi + 1] > half:
        hi += 1
    outside = np.r_[r[:lo], r[hi + 1:]]
    second = float(np.nanmax(outside)) if np.any(np.isfinite(outside)) else float("nan")
    conf = float(np.clip(r[p] - max(second if np.isfinite(second) else 0.0, 0.0), 0.0, 1.0))
    return Alignment(
        shift_m=float(-lag_bins * bin_length_m),
        confidence=conf,
        peak_r=float(r[p]),
        second_r=second,
        overlap_m=float(overlap[p]),
        lags_m=lags_m,
        correlation=r,
    )


@dataclass(frozen=True)
class SegmentTable:
    """Mean amplitude per run and segment, and statistics over runs.

    Attributes
    ----------
    start_m : numpy.ndarray
        Segment starts, m on the km axis.
    matrix : numpy.ndarray
        (runs, segments) mean amplitude, m/s² (NaN = no data).
    mean, spread : numpy.ndarray
        Mean and standard deviation (ddof = 1; NaN with fewer than 2 runs) over runs.
    change : numpy.ndarray
        Last minus first run with data in the segment (runs in date order), m/s²;
        with speeds given, NaN where those two passed at speeds differing by more
        than the tolerance (the matched-speed rule).
    speed : numpy.ndarray or None
        (runs, segments) mean speed, m/s (when speeds were given).
    """

    start_m: np.ndarray
    matrix: np.ndarray
    mean: np.ndarray
    spread: np.ndarray
    change: np.ndarray
    speed: np.ndarray | None = None


def segment_table(
    runs: list[tuple[np.ndarray, np.ndarray]],
    shifts_m: list[float],
    *,
    bin_length_m: float = 0.25,
    segment_m: float = DEFAULT_SEGMENT_M,
    min_coverage: float = 0.5,
    speeds: list[np.ndarray] | None = None,
    speed_tolerance: float = DEFAULT_SPEED_TOLERANCE,
    statistic: str = "mean",
) -> SegmentTable:
    """Per-segment mean (or median) value of several runs after shifting each by its alignment.

    Parameters
    ----------
    runs : list of (bins, amplitude)
        Bin indices and amplitude (m/s²) of each run, in date order.
    shifts_m : list of float
        Shift of each run (m, added to its positions; NaN counts as 0).
    bin_length_m, segment_m : float
        Bin and segment length, m.
    min_coverage : float
        A run's segment mean needs this fraction of the segment's bins.
    speeds : list of numpy.ndarray, optional
        Speed of each run's bins (m/s): the table then holds the segment speeds and
        ``change`` compares two runs only where their speeds differ by at most
        ``speed_tolerance`` (relative).
    speed_tolerance : float
        A change needs the two runs at matched speed, ``|ln(v_last / v_first)| <= ln(1 + speed_tolerance)``
        (:func:`app.analysis.speed_match.speeds_matched`).
    statistic : {"mean", "median"}
        Of a run's bins in a segment: ``"median"`` for a value whose zero is a median — the stiffness index,
        ``ln A`` less the reference curve fitted to 10 m blocks' medians
        (:mod:`app.analysis.stiffness.reference_curve`): on rough rails a bin's ``ln A`` has a long low tail
        (the rails' response cancelling the support's at a bin), so the bins' mean lies below their median
        and a mean index read every 100 m of issue 33's rough line 0.1–0.6 below typical track. The speed
        stays the mean.
    """
    if len(runs) != len(shifts_m) or (speeds is not None and len(speeds) != len(runs)):
        raise ValueError("runs, shifts_m, speeds: must have equal lengths")
    if statistic not in ("mean", "median"):
        raise ValueError(f"statistic: must be 'mean' or 'median', got {statistic!r}")
    if not segment_m > 0 or not bin_length_m > 0:
        raise ValueError("segment_m, bin_length_m: must be > 0")
    per_run = []
    for i, ((bins, amp), shift) in enumerate(zip(runs, shifts_m, strict=True)):
        amp = np.asarray(amp, dtype=np.float64)
        x = (np.asarray(bins, dtype=np.float64) + 0.5) * bin_length_m + (shift if np.isfinite(shift) else 0.0)
        ok = np.isfinite(amp)
        seg = np.floor(x[ok] / segment_m).astype(np.int64)
        v = np.asarray(speeds[i], dtype=np.float64)[ok] if speeds is not None else None
        per_run.append((seg, amp[ok], v))
    all_segs = np.unique(np.concatenate([s for s, _, _ in per_run])) if per_run else np.zeros(0, np.int64)
    matrix = np.full((len(runs), all_segs.size), np.nan)
    speed = np.full((len(runs), all_segs.size), np.nan) if speeds is not None else None
    need = min_coverage * segment_m / bin_length_m
    for i, (seg, amp, v) in enumerate(per_run):
        if seg.size == 0:
            continue
        j = np.searchsorted(all_segs, seg)
        c = np.bincount(j, minlength=all_segs.size)
        if statistic == "median":
            value = group_median(amp, j, all_segs.size)
        else:
            value = np.bincount(j, weights=amp, minlength=all_segs.size) / np.maximum(c, 1)
        matrix[i] = np.where(c >= need, value, np.nan)
        if speed is not None:
            speed[i] = np.where(c >= need, np.bincount(j, weights=v, minlength=all_segs.size) / np.maximum(c, 1),
                                np.nan)
    n_ok = np.isfinite(matrix).sum(axis=0)
    with np.errstate(invalid="ignore"):
        mean = np.where(n_ok > 0, np.nansum(matrix, axis=0) / np.maximum(n_ok, 1), np.nan)
        dev = np.where(np.isfinite(matrix), matrix - mean, 0.0)
        spread = np.where(n_ok >= 2, np.sqrt((dev**2).sum(axis=0) / np.maximum(n_ok - 1, 1)), np.nan)
    change = np.full(all_segs.size, np.nan)
    for j in range(all_segs.size):
        have = np.flatnonzero(np.isfinite(matrix[:, j]))
        if have.size < 2:
            continue
        first, last = have[0], have[-1]
        if speed is not None and not speeds_matched(speed[last, j], speed[first, j], speed_tolerance):
            continue
        change[j] = matrix[last, j] - matrix[first, j]
    return SegmentTable(all_segs * segment_m, matrix, mean, spread, change, speed)
