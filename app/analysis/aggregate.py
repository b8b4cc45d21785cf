"""Aggregation of 25 cm profiles to longer segments, and decimation for display.

* :func:`aggregate_profile` groups 25 cm rows into segments of ``level_m``
  (1 / 10 / 100 m, ...) and gives the NaN-aware mean, max and 95th percentile
  of every column per segment. Segment ``g`` of a row with bin index ``b`` is
  ``floor(b * bin_length / level_m)``; it spans ``[g, g + 1) * level_m`` m.
  A 1-σ column (name ending in ``_sd``, e.g. ``sleeper_amp_sd``) aggregates to
  the 1-σ of the segment's mean (:func:`app.analysis.uncertainty.segment_sd`:
  the bins' errors are correlated along the track), not to the mean of the bins' 1-σ;
  where ``df`` holds ``<col>_shared`` (e.g. ``sleeper_amp_sd_shared``), that part of
  it is shared along the floor window, and ``<col>_shared`` itself aggregates to the
  shared part of the segment's 1-σ.
* :func:`decimate_for_display` reduces a long curve to at most ``max_points``
  points for plotting while keeping the local minima and maxima (peaks
  survive), and always the global minimum and maximum.
* :func:`display_levels` ranks the bins of a profile once, when it is stored,
  so that a display of any km range at any zoom can read only the few rows
  that carry its peaks (a min–max pyramid).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from app.analysis.uncertainty import segment_sd

__all__ = ["aggregate_profile", "decimate_for_display", "display_indices", "display_levels", "DISPLAY_LEVEL_BASE"]

#: bins per bucket grow by this factor from one display level to the next
DISPLAY_LEVEL_BASE = 4


def _level_ratio(level_m: float, bin_length: float) -> int:
    try:
        lvl = float(level_m)
        bl = float(bin_length)
    except (TypeError, ValueError):
        raise ValueError(
            f"level_m and bin_length must be numbers, got {level_m!r}, {bin_length!r}"
        ) from None
    if not np.isfinite(bl) or bl <= 0:
        raise ValueError(f"bin_length must be a finite number > 0 m, got {bin_length!r}")
    if not np.isfinite(lvl) or lvl <= 0:
        raise ValueError(f"level_m must be a finite number > 0 m, got {level_m!r}")
    ratio = lvl / bl
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-9 * max(ratio, 1.0):
        raise ValueError(
            f"level_m must be a positive integer multiple of bin_length={bl} m, got {level_m!r}"
        )
    return int(k)


def _group_percentile(
    values: np.ndarray, group_start: np.ndarray, group_id: np.ndarray, q: float
) -> np.ndarray:
    """NaN-aware per-group percentile (linear interpolation, like numpy's default).

    ``values`` are sorted by group (``group_id`` non-decreasing, groups start at
    ``group_start``).
    """
    ng = group_start.size
    finite = np.isfinite(values)
    # Sort by (group, value) with the NaNs of each group at its end.
    key = np.where(finite, values, np.inf)
    order = np.lexsort((~finite, key, group_id))
    v_sorted = values[order]
    n_fin = np.bincount(group_id, weights=finite.astype(np.float64), minlength=ng).astype(np.int64)
    out = np.full(ng, np.nan)
    has = n_fin > 0
    pos = q / 100.0 * (n_fin[has] - 1)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, n_fin[has] - 1)
    frac = pos - lo
    start = group_start[has]
    v_lo = v_sorted[start + lo]
    v_hi = v_sorted[start + hi]
    out[has] = v_lo + frac * (v_hi - v_lo)
    return out


def aggregate_profile(
    df: pd.DataFrame,
    level_m: float,
    columns: Sequence[str],
    bin_length: float = 0.25,
    *,
    resolution_m: float = 3.0,
    filter_order: int = 2,
) -> pd.DataFrame:
    """Aggregate a 25 cm profile to segments of ``level_m``.

    Parameters
    ----------
    df : pandas.DataFrame
        One row per bin with an int ``bin`` column (``floor(track_m / bin_length)``)
        and the ``columns`` to aggregate. Bins must be unique (aggregate one wheel
        at a time); row order does not matter.
    level_m : float
        Segment length, m; a positive integer multiple of ``bin_length``
        (``level_m == bin_length`` returns one segment per bin).
    columns : sequence of str
        Numeric columns of ``df`` to aggregate (e.g. ``order_amp_01`` in m/s²).
    bin_length : float, optional
        Bin length of ``df``, m (default 0.25).
    resolution_m, filter_order : optional, keyword-only
        The track orders' resolution (m) and q the profile was processed with
        (defaults: those of :class:`app.analysis.settings.ProcessingSettings`): the
        along-track correlation of a 1-σ column's bins.

    Returns
    -------
    pandas.DataFrame
        One row per segment that holds at least one bin, sorted along the track:
        ``km_from``, ``km_to`` (segment bounds, km), ``n_bins`` (number of rows of
        ``df`` in the segment), then ``<col>_mean``, ``<col>_max`` and ``<col>_p95``
        for every column (NaN values ignored; NaN where a segment has no finite value).

        For a 1-σ column (``<col>`` ending in ``_sd``) ``<col>_mean`` is the 1-σ of
        the mean of the segment's bins (:func:`app.analysis.uncertainty.segment_sd`,
        with ``<col>_shared`` of ``df`` as its shared part where ``df`` holds it;
        ``<col>_shared`` aggregates to that part of the segment's 1-σ); their
        ``_max`` and ``_p95`` are those of the bins'.

    Raises
    ------
    ValueError
        If ``level_m`` is not a multiple of ``bin_length``, ``df`` lacks ``bin`` or
        one of ``columns``, or ``bin`` is not unique integers.
    """
    k = _level_ratio(level_m, bin_length)
    level = k * float(bin_length)
    if not isinstance(df, pd.DataFrame):
        raise ValueError("df must be a pandas DataFrame")
    if isinstance(columns, str):
        columns = [columns]
    columns = list(columns)
    if "bin" not in df.columns:
        raise ValueError("df must have a 'bin' column")
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise ValueError(f"columns {missing} are not in df")

    out_cols = ["km_from", "km_to", "n_bins"] + [
        f"{c}_{s}" for c in columns for s in ("mean", "max", "p95")
    ]
    bins = df["bin"].to_numpy()
    if bins.size == 0:
        return pd.DataFrame(
            {c: pd.Series(dtype=np.int64 if c == "n_bins" else np.float64) for c in out_cols}
        )
    if not np.issubdtype(bins.dtype, np.integer):
        raise ValueError(f"df['bin'] must hold integers, got dtype {bins.dtype}")
    bins = bins.astype(np.int64)
    order = np.argsort(bins, kind="stable")
    bins = bins[order]
    if np.any(np.diff(bins) == 0):
        raise ValueError("df['bin'] must be unique (aggregate one wheel at a time)")

    seg = np.floor_divide(bins, k)
    starts = np.flatnonzero(np.r_[True, np.diff(seg) != 0])
    seg_ids = seg[starts]
    ng = starts.size
    group_id = np.repeat(np.arange(ng), np.diff(np.r_[starts, bins.size]))
    n_bins = np.diff(np.r_[starts, bins.size]).astype(np.int64)

    result: dict[str, np.ndarray] = {
        "km_from": seg_ids * level / 1000.0,
        "km_to": (seg_ids + 1) * level / 1000.0,
        "n_bins": n_bins,
    }
    for c in columns:
        v = pd.to_numeric(df[c], errors="raise").to_numpy(dtype=np.float64, na_value=np.nan)
        v = v[order]
        finite = np.isfinite(v)
        n_fin = np.add.reduceat(finite.astype(np.int64), starts)
        total = np.add.reduceat(np.where(finite, v, 0.0), starts)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(n_fin > 0, total / np.maximum(n_fin, 1), np.nan)
        vmax = np.maximum.reduceat(np.where(finite, v, -np.inf), starts)
        vmax = np.where(n_fin > 0, vmax, np.nan)
        if c.endswith("_sd") or c.endswith("_sd_shared"):  # the 1-σ of the segment's mean
            if c.endswith("_sd_shared"):
                shared = v
            elif f"{c}_shared" in df.columns:
                shared = pd.to_numeric(df[f"{c}_shared"], errors="raise").to_numpy(
                    dtype=np.float64, na_value=np.nan)[order]
            else:
                shared = None
            mean = np.full(ng, np.nan)
            segs, sd_mean = segment_sd(bins, v, level, bin_length, resolution_m, filter_order, shared=shared)
            mean[np.searchsorted(seg_ids, segs)] = sd_mean
        result[f"{c}_mean"] = mean
        result[f"{c}_max"] = vmax
        result[f"{c}_p95"] = _group_percentile(v, starts, group_id, 95.0)
    return pd.DataFrame(result, columns=out_cols)


def _minmax_indices(values: np.ndarray, n_buckets: int) -> np.ndarray:
    """Indices of the min and max of each of ``n_buckets`` equal-count buckets.

    NaN values are ignored; a bucket without a finite value contributes its first
    index (so gaps stay visible as NaN).
    """
    n = values.size
    edges = np.linspace(0, n, n_buckets + 1).astype(np.int64)
    edges = np.unique(edges)
    starts = edges[:-1]
    sizes = np.diff(edges)
    finite = np.isfinite(values)
    n_fin = np.add.reduceat(finite.astype(np.int64), starts)
    # O(n): the extreme of each bucket by reduceat, then its first index in the bucket
    rev = n - np.arange(n)  # larger for earlier indices
    out = []
    for key in (np.where(finite, -values, -np.inf), np.where(finite, values, -np.inf)):
        best = np.maximum.reduceat(key, starts)
        hit = key == np.repeat(best, sizes)
        first = n - np.maximum.reduceat(np.where(hit, rev, 0), starts)
        first[n_fin == 0] = starts[n_fin == 0]
        out.append(first)
    return np.concatenate(out)


def _tsdownsample_indices(km: np.ndarray, values: np.ndarray, n_out: int) -> np.ndarray | None:
    try:
        from tsdownsample import MinMaxLTTBDownsampler  # type: ignore[import-not-found]
    except ImportError:
        return None
    if not np.all(np.isfinite(values)) or np.any(np.diff(km) <= 0):
        return None  # tsdownsample wants strictly increasing x and finite y
    try:
        idx = MinMaxLTTBDownsampler().downsample(km, values, n_out=n_out)
    except Exception:  # any failure of the optional backend: fall back to min-max
        return None
    idx = np.asarray(idx, dtype=np.int64)
    if idx.ndim != 1 or idx.size > n_out or np.any((idx < 0) | (idx >= km.size)):
        return None
    return idx


def decimate_for_display(
    km: np.ndarray,
    values: np.ndarray,
    max_points: int,
    *,
    use_tsdownsample: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Decimate a curve for plotting while keeping its peaks.

    Parameters
    ----------
    km : array_like
        (n,) positions, km (finite; need not be sorted).
    values : array_like
        (n,) values (NaN allowed: gaps).
    max_points : int
        Maximum number of points returned, >= 4.
    use_tsdownsample : bool, optional
        Use the ``tsdownsample`` package's MinMaxLTTB when it is importable and
        the input suits it (finite values, strictly increasing km). Otherwise a
        min-max decimation over equal-count buckets is used.

    Returns
    -------
    km_out, values_out : numpy.ndarray
        At most ``max_points`` points of the input, sorted by km. The first and
        last points and the global minimum and maximum are always kept. If the
        input has at most ``max_points`` points it is returned whole (sorted).

    Raises
    ------
    ValueError
        If ``km`` and ``values`` differ in shape, are not 1-D, ``km`` is not
        finite, or ``max_points`` < 4.
    """
    x = np.asarray(km, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    idx = display_indices(x, y, max_points, use_tsdownsample=use_tsdownsample)
    return x[idx], y[idx]


def display_indices(
    km: np.ndarray,
    values: np.ndarray,
    max_points: int,
    *,
    use_tsdownsample: bool = True,
) -> np.ndarray:
    """Indices of the points :func:`decimate_for_display` keeps.

    Use it to decimate several columns of a table by the peaks of one of them
    (e.g. the rows of a profile by the sleeper-passage amplitude).

    Parameters
    ----------
    km, values, max_points, use_tsdownsample
        As in :func:`decimate_for_display`.

    Returns
    -------
    numpy.ndarray of int
        At most ``max_points`` indices into ``km``, ordered by km (all indices,
        ordered by km, when the input has at most ``max_points`` points).

    Raises
    ------
    ValueError
        As :func:`decimate_for_display`.
    """
    x = np.asarray(km, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"km must be 1-D, got shape {x.shape}")
    if y.shape != x.shape:
        raise ValueError(f"values must have the shape of km {x.shape}, got {y.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("km must be finite (found NaN or inf)")
    if isinstance(max_points, bool) or int(max_points) != max_points or max_points < 4:
        raise ValueError(f"max_points must be an integer >= 4, got {max_points!r}")
    max_points = int(max_points)

    order = np.argsort(x, kind="stable")
    x, y = x[order], y[order]
    n = x.size
    if n <= max_points:
        return order

    finite = np.isfinite(y)
    extremes: list[int] = [0, n - 1]
    if finite.any():
        extremes += [int(np.nanargmin(y)), int(np.nanargmax(y))]
    budget = max_points - len(extremes)

    # Interior points: at most ``budget`` so that, with the extremes, the total
    # never exceeds max_points.
    idx = None
    if use_tsdownsample and budget >= 3:
        idx = _tsdownsample_indices(x, y, budget)
    if idx is None:
        idx = _minmax_indices(y, budget // 2) if budget >= 2 else np.empty(0, dtype=np.int64)
    idx = np.unique(np.concatenate([idx, np.asarray(extremes, dtype=np.int64)]))
    return order[idx]


def _bucket_extremes(bins: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Positions of the first minimum of ``lo`` and first maximum of ``hi`` per run of equal ``bins``."""
    starts = np.flatnonzero(np.r_[True, bins[1:] != bins[:-1]])
    group = np.cumsum(np.r_[False, bins[1:] != bins[:-1]])
    out = []
    for vals, reduce in ((lo, np.minimum), (hi, np.maximum)):
        best = reduce.reduceat(vals, starts)
        hit = np.flatnonzero(vals == best[group])
        # the first hit of every group (hits are in position order)
        out.append(hit[np.r_[True, group[hit][1:] != group[hit][:-1]]])
    chosen = np.zeros(bins.size, dtype=bool)
    chosen[out[0]] = chosen[out[1]] = True
    return np.flatnonzero(chosen)


def display_levels(bins: np.ndarray, values: np.ndarray, *, base: int = DISPLAY_LEVEL_BASE) -> np.ndarray:
    """Display level of every bin of a profile: a min–max pyramid over the bin index.

    Level ``k`` groups the bins into buckets of ``base**k`` consecutive bin
    indices (bucket ``floor(bin / base**k)``). A bin has level ``>= k`` if it
    is the (first) minimum or maximum of ``values`` in its level-``k`` bucket.
    Reading the rows of level ``>= k`` of any km range therefore gives at most
    two rows per bucket and keeps every peak that a min–max decimation to
    buckets of ``base**k`` bins would keep. The first and last bin of the
    profile get the top level (the first whose one bucket holds the whole
    profile; for a profile with bins on both sides of 0, which no bucket
    holds, the first with one bucket on either side), so every level spans
    the whole profile.

    Parameters
    ----------
    bins : array_like of int
        (n,) bin indices of one wheel's profile (unique, any order).
    values : array_like of float
        (n,) values that rank the bins (e.g. the sleeper-passage amplitude,
        m/s²). NaN or inf counts as missing: a bucket with no finite value
        keeps its first bin, so gaps stay visible.
    base : int, optional
        Bucket growth factor between levels (>= 2).

    Returns
    -------
    numpy.ndarray of int16
        (n,) level of every bin, in the input order; 0 for bins that only
        the full-resolution level holds.

    Raises
    ------
    ValueError
        If the arrays are not 1-D of one shape, ``bins`` are not unique
        integers, or ``base`` < 2.

    Notes
    -----
    The levels are nested: the minimum (maximum) of a bucket is the minimum
    (maximum) of its sub-bucket too, so level ``k`` is computed from the bins of
    level ``k − 1`` only, and the whole pyramid costs O(n log n) for the sort.
    """
    if isinstance(base, bool) or int(base) != base or base < 2:
        raise ValueError(f"base must be an integer >= 2, got {base!r}")
    b = np.asarray(bins)
    y = np.asarray(values, dtype=np.float64)
    if b.ndim != 1:
        raise ValueError(f"bins must be 1-D, got shape {b.shape}")
    if y.shape != b.shape:
        raise ValueError(f"values must have the shape of bins {b.shape}, got {y.shape}")
    if b.size and b.dtype.kind not in "iu":
        raise ValueError(f"bins must be integers, got dtype {b.dtype}")
    levels = np.zeros(b.size, dtype=np.int16)
    if b.size == 0:
        return levels
    b = b.astype(np.int64)
    order = np.argsort(b, kind="stable")
    sb, sy = b[order], y[order]
    if np.any(sb[1:] == sb[:-1]):
        raise ValueError("bins must be unique")
    finite = np.isfinite(sy)
    lo = np.where(finite, sy, np.inf)
    hi = np.where(finite, sy, -np.inf)
    # missing values tie at ±inf: the bucket's first bin wins both
    keep = np.arange(sb.size)
    first, last = int(sb[0]), int(sb[-1])
    k, span = 0, 1
    # up to the first level whose single bucket holds the whole profile; bins on
    # both sides of 0 never share a bucket: there, up to the first of two buckets
    while k == 0 or (first // span != last // span and not (first < 0 <= last and span > last - first)):
        k, span = k + 1, span * int(base)
        keep = keep[_bucket_extremes(sb[keep] // span, lo[keep], hi[keep])]
        levels[order[keep]] = k
    levels[order[[0, -1]]] = k
    return levels
