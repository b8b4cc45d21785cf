"""Tests of app.analysis.aggregate: segment aggregation and display decimation."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from app.analysis import aggregate
from app.analysis.aggregate import aggregate_profile, decimate_for_display


def _profile(rng: np.random.Generator) -> pd.DataFrame:
    bins = np.sort(rng.choice(np.arange(-800, 4000), size=3000, replace=False))
    a = rng.gamma(2.0, 0.5, bins.size)
    a[rng.random(bins.size) < 0.15] = np.nan
    a[(bins >= 1200) & (bins < 1240)] = np.nan  # one 10 m segment entirely NaN
    b = rng.normal(20.0, 3.0, bins.size)
    df = pd.DataFrame({"bin": bins, "km": (bins + 0.5) * 0.25e-3, "a": a, "b": b})
    return df.sample(frac=1.0, random_state=4)  # row order must not matter


@pytest.mark.parametrize("level_m", [1.0, 10.0, 100.0])
def test_matches_pandas_groupby(level_m: float) -> None:
    df = _profile(np.random.default_rng(5))
    got = aggregate_profile(df, level_m, ["a", "b"])
    k = round(level_m / 0.25)
    g = df.assign(seg=df["bin"] // k).groupby("seg")
    ref = pd.DataFrame(
        {
            "n_bins": g.size(),
            "a_mean": g["a"].mean(),
            "a_max": g["a"].max(),
            "a_p95": g["a"].quantile(0.95),
            "b_mean": g["b"].mean(),
            "b_max": g["b"].max(),
            "b_p95": g["b"].quantile(0.95),
        }
    ).sort_index()
    assert list(got.columns) == [
        "km_from",
        "km_to",
        "n_bins",
        "a_mean",
        "a_max",
        "a_p95",
        "b_mean",
        "b_max",
        "b_p95",
    ]
    np.testing.assert_allclose(got["km_from"], ref.index.to_numpy() * level_m / 1000, rtol=1e-15)
    np.testing.assert_allclose(got["km_to"] - got["km_from"], level_m / 1000, rtol=1e-9)
    np.testing.assert_array_equal(got["n_bins"], ref["n_bins"])
    for c in ref.columns[1:]:
        np.testing.assert_allclose(got[c].to_numpy(), ref[c].to_numpy(), rtol=1e-12, err_msg=c)
    if level_m == 10.0:
        assert got.loc[np.isclose(got["km_from"], 0.3), "a_mean"].isna().all()


def test_level_equal_to_bin_length_is_identity() -> None:
    df = _profile(np.random.default_rng(6))
    got = aggregate_profile(df, 0.25, ["a"])
    srt = df.sort_values("bin")
    np.testing.assert_allclose(got["km_from"], srt["bin"].to_numpy() * 0.25e-3, rtol=1e-15)
    np.testing.assert_array_equal(got["n_bins"], 1)
    for s in ("mean", "max", "p95"):
        np.testing.assert_array_equal(got[f"a_{s}"].to_numpy(), srt["a"].to_numpy())


def test_aggregate_validation() -> None:
    df = pd.DataFrame({"bin": [0, 1, 2], "a": [1.0, 2.0, 3.0]})
    with pytest.raises(ValueError, match="level_m"):
        aggregate_profile(df, 0.3, ["a"])
    with pytest.raises(ValueError, match="level_m"):
        aggregate_profile(df, 0.0, ["a"])
    with pytest.raises(ValueError, match="columns"):
        aggregate_profile(df, 1.0, ["nope"])
    with pytest.raises(ValueError, match="unique"):
        aggregate_profile(pd.DataFrame({"bin": [0, 0], "a": [1.0, 2.0]}), 1.0, ["a"])
    empty = aggregate_profile(df.iloc[:0], 1.0, ["a"])
    assert empty.empty and "a_p95" in empty.columns


def _spiky(rng: np.random.Generator, n: int = 200_000) -> tuple[np.ndarray, np.ndarray]:
    km = np.linspace(10.0, 60.0, n)
    y = np.cumsum(rng.normal(0.0, 1.0, n)) * 0.01
    return km, y


@pytest.mark.parametrize("use_ts", [False, True])
def test_decimation_keeps_global_extremes_and_order(use_ts: bool) -> None:
    rng = np.random.default_rng(7)
    km, y = _spiky(rng)
    y[123_457] = 50.0
    y[4_321] = -40.0
    perm = rng.permutation(km.size)  # unsorted input
    xo, yo = decimate_for_display(km[perm], y[perm], 1000, use_tsdownsample=use_ts)
    assert xo.size <= 1000
    assert np.all(np.diff(xo) > 0)
    assert yo.max() == 50.0 and xo[np.argmax(yo)] == km[123_457]
    assert yo.min() == -40.0 and xo[np.argmin(yo)] == km[4_321]
    assert xo[0] == km[0] and xo[-1] == km[-1]
    # every returned point is an input point
    np.testing.assert_array_equal(np.interp(xo, km, y), yo)


def test_minmax_fallback_keeps_every_separated_peak_and_gaps(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rng = np.random.default_rng(8)
    km, y = _spiky(rng, 100_000)
    peaks = np.arange(2_000, 98_000, 9_000)  # > 2 buckets apart at 400 points
    y[peaks] = 30.0 + np.arange(peaks.size)
    y[50_000:52_000] = np.nan  # standing train: a gap wider than a bucket
    monkeypatch.setattr(aggregate, "_tsdownsample_indices", lambda *a: None)
    xo, yo = decimate_for_display(km, y, 400)
    assert xo.size <= 400
    for p in peaks:
        assert km[p] in xo
    assert np.isnan(yo).any()
    assert np.nanmax(yo) == y[peaks].max()


def test_decimation_short_input_and_validation() -> None:
    xo, yo = decimate_for_display(np.array([3.0, 1.0, 2.0]), np.array([30.0, 10.0, 20.0]), 10)
    np.testing.assert_array_equal(xo, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(yo, [10.0, 20.0, 30.0])
    with pytest.raises(ValueError, match="max_points"):
        decimate_for_display(np.arange(10.0), np.arange(10.0), 3)
    with pytest.raises(ValueError, match="values"):
        decimate_for_display(np.arange(10.0), np.arange(9.0), 5)
    with pytest.raises(ValueError, match="km"):
        decimate_for_display(np.array([0.0, np.nan]), np.arange(2.0), 5)


# --- display levels (min–max pyramid) ----------------------------------------
def _levels_by_brute_force(bins: np.ndarray, values: np.ndarray, base: int) -> np.ndarray:
    """Slow reference: for every level and bucket, the first min and max by a Python loop."""
    order = np.argsort(bins, kind="stable")
    b, y = bins[order], values[order]
    levels = np.zeros(b.size, dtype=int)
    k = 0
    while True:
        k += 1
        span = base**k
        kept = set()
        for g in np.unique(b // span):
            members = np.flatnonzero(b // span == g)
            vals = [y[i] if np.isfinite(y[i]) else None for i in members]
            finite = [(v, i) for v, i in zip(vals, members, strict=True) if v is not None]
            if not finite:
                kept.add(int(members[0]))
                continue
            kept.add(min(finite, key=lambda t: (t[0], t[1]))[1])
            kept.add(min(finite, key=lambda t: (-t[0], t[1]))[1])
        for i in kept:
            levels[i] = k
        if len(np.unique(b // span)) == 1:
            break
        if b[0] < 0 <= b[-1] and span > b[-1] - b[0]:  # across 0: two buckets at the top
            break
    top = levels.max()
    levels[[0, -1]] = max(top, 1)
    out = np.empty_like(levels)
    out[order] = levels
    return out


@pytest.mark.parametrize(
    ("n", "base", "seed", "first"),
    [(1, 4, 0, 17), (2, 4, 1, 17), (3, 2, 2, 17), (1000, 4, 3, 17), (777, 3, 4, 17),
     (1000, 4, 6, -1200), (2, 4, 7, -1), (500, 2, 8, -1500)],
)
def test_display_levels_match_brute_force(n: int, base: int, seed: int, first: int) -> None:
    """Bins anywhere on the axis, negative ones (track km < 0) and across 0 included."""
    rng = np.random.default_rng(seed)
    bins = rng.permutation(np.arange(n) * 3 + first)  # gaps in the bin numbers, any order
    values = rng.lognormal(0, 0.5, n).round(1)  # ties
    values[rng.random(n) < 0.1] = np.nan
    values[rng.random(n) < 0.02] = np.inf
    if n > 300:
        values[100:300] = np.nan  # whole buckets without a value
    got = aggregate.display_levels(bins, values, base=base)
    assert got.dtype == np.int16
    np.testing.assert_array_equal(got, _levels_by_brute_force(bins, values, base))


def test_display_levels_keep_two_rows_per_bucket_and_the_peaks() -> None:
    rng = np.random.default_rng(5)
    n = 100_000
    bins = np.arange(n)
    values = rng.lognormal(0, 0.4, n)
    levels = aggregate.display_levels(bins, values)
    for k in range(1, int(levels.max()) + 1):
        kept = bins[levels >= k]
        buckets, per_bucket = np.unique(kept // 4**k, return_counts=True)
        inner = (buckets != 0) & (buckets != (n - 1) // 4**k)  # the ends are kept besides min and max
        assert per_bucket[inner].max(initial=0) <= 2 and per_bucket.max() <= 4
        assert {0, n - 1, int(np.argmax(values)), int(np.argmin(values))} <= set(kept.tolist())
    # nested: each level is half the bins of the level below or fewer (plus the ends)
    counts = [int(np.sum(levels >= k)) for k in range(int(levels.max()) + 1)]
    assert all(c1 <= c0 for c0, c1 in zip(counts, counts[1:], strict=False))
    assert counts[1] <= n // 2 + 2


def test_display_levels_validation() -> None:
    with pytest.raises(ValueError, match="base"):
        aggregate.display_levels([1, 2], [1.0, 2.0], base=1)
    with pytest.raises(ValueError, match="shape"):
        aggregate.display_levels([1, 2], [1.0])
    with pytest.raises(ValueError, match="unique"):
        aggregate.display_levels([1, 1], [1.0, 2.0])
    with pytest.raises(ValueError, match="integers"):
        aggregate.display_levels([1.5, 2.0], [1.0, 2.0])
    assert aggregate.display_levels(np.array([], dtype=int), []).size == 0
