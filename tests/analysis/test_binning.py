"""Tests of app.analysis.binning: exact mergeability of per-bin weighted sums."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from app.analysis.binning import BinSums, position_to_bin


def _samples(rng: np.random.Generator, n: int = 20_000) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    track = np.cumsum(rng.uniform(0.0, 0.02, n)) - 30.0  # m, crosses zero
    speed = rng.uniform(5.0, 45.0, n)
    amp = rng.normal(1.0, 0.3, n)
    amp[rng.random(n) < 0.1] = np.nan
    return track, {"speed": speed, "amp": amp}


def _assert_same(a: BinSums, b: BinSums) -> None:
    np.testing.assert_array_equal(a.bins, b.bins)
    np.testing.assert_array_equal(a.count, b.count)
    np.testing.assert_allclose(a.weight, b.weight, rtol=1e-12, atol=0)
    assert list(a.sums) == list(b.sums) and set(a.sq) == set(b.sq)
    for k in a.sums:
        np.testing.assert_allclose(a.sums[k], b.sums[k], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(a.vweight[k], b.vweight[k], rtol=1e-12, atol=0)
    for k in a.sq:
        np.testing.assert_allclose(a.sq[k], b.sq[k], rtol=1e-12, atol=1e-12)


def test_position_to_bin_floors_and_validates() -> None:
    got = position_to_bin(np.array([-0.1, -0.25, 0.0, 0.2499, 0.25, 1000.1]))
    np.testing.assert_array_equal(got, [-1, -1, 0, 0, 1, 4000])
    assert got.dtype == np.int64
    np.testing.assert_array_equal(position_to_bin(np.array([2.5]), bin_length=1.0), [2])
    with pytest.raises(ValueError, match="track_m"):
        position_to_bin(np.array([0.0, np.nan]))
    with pytest.raises(ValueError, match="bin_length"):
        position_to_bin(np.array([0.0]), bin_length=0.0)


def test_split_and_merge_equals_whole() -> None:
    rng = np.random.default_rng(1)
    track, values = _samples(rng)
    bins = position_to_bin(track)
    w = rng.uniform(0.1, 1.0, track.size)
    whole = BinSums.from_samples(bins, w, values, squares=["amp"])
    cuts = [0, 4_999, 5_000, 13_337, track.size]  # cuts inside bins; one part of one sample
    parts = [
        BinSums.from_samples(
            bins[a:b], w[a:b], {k: v[a:b] for k, v in values.items()}, squares=["amp"]
        )
        for a, b in zip(cuts[:-1], cuts[1:], strict=True)
    ]
    _assert_same(BinSums.merge_all(parts), whole)
    _assert_same(BinSums.merge_all(parts[::-1]), whole)
    pairwise = parts[0]
    for p in parts[1:]:
        pairwise = pairwise.merge(p)
    _assert_same(pairwise, whole)
    # bins are disjoint in shuffled parts too (samples need not be sorted)
    perm = rng.permutation(track.size)
    half = track.size // 2
    sh = [
        BinSums.from_samples(bins[i], w[i], {k: v[i] for k, v in values.items()}, squares=["amp"])
        for i in (perm[:half], perm[half:])
    ]
    _assert_same(sh[0].merge(sh[1]), whole)


def test_crossfaded_chunks_reproduce_plain_mean() -> None:
    rng = np.random.default_rng(2)
    track, values = _samples(rng, 12_000)
    bins = position_to_bin(track)
    # three chunks with 1500-sample overlaps and linear crossfades summing to 1
    n = track.size
    edges = [(0, 5_500), (4_000, 9_500), (8_000, n)]
    weights = []
    for i, (a, b) in enumerate(edges):
        w = np.ones(b - a)
        if i > 0:
            ov = edges[i - 1][1] - a
            w[:ov] = np.linspace(0.0, 1.0, ov + 2)[1:-1]
        if i < len(edges) - 1:
            ov = b - edges[i + 1][0]
            w[-ov:] = 1.0 - np.linspace(0.0, 1.0, ov + 2)[1:-1]
        weights.append(w)
    total = np.zeros(n)
    for (a, b), w in zip(edges, weights, strict=True):
        total[a:b] += w
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-15)

    parts = [
        BinSums.from_samples(
            bins[a:b], w, {k: v[a:b] for k, v in values.items()}, squares=["amp", "speed"]
        )
        for (a, b), w in zip(edges, weights, strict=True)
    ]
    got = BinSums.merge_all(parts).finalize(0.25)

    df = pd.DataFrame({"bin": bins, **values})
    df["amp2"] = df["amp"] ** 2
    ref = df.groupby("bin").agg(
        n=("speed", "size"), speed=("speed", "mean"), amp=("amp", "mean"), amp2=("amp2", "mean")
    )
    np.testing.assert_array_equal(got["bin"].to_numpy(), ref.index.to_numpy())
    np.testing.assert_array_equal(got["n_samples"].to_numpy(), ref["n"].to_numpy())
    np.testing.assert_allclose(got["speed"], ref["speed"], rtol=1e-12)
    np.testing.assert_allclose(got["amp"], ref["amp"], rtol=1e-12)  # NaN where all NaN
    np.testing.assert_allclose(got["amp_rms"], np.sqrt(ref["amp2"]), rtol=1e-12)
    np.testing.assert_allclose(got["km"], (ref.index.to_numpy() + 0.5) * 0.25 / 1000, rtol=1e-15)
    assert list(got.columns) == ["bin", "km", "n_samples", "speed", "amp", "speed_rms", "amp_rms"]


def test_nan_excludes_only_that_value_and_zero_weight_drops() -> None:
    bins = np.array([0, 0, 0, 1, 1, 2])
    w = np.array([1.0, 0.5, 1.0, 1.0, 1.0, 0.0])
    a = np.array([1.0, 4.0, np.nan, np.nan, np.nan, 7.0])
    b = np.array([2.0, 2.0, 5.0, 3.0, 1.0, 9.0])
    s = BinSums.from_samples(bins, w, {"a": a, "b": b}, squares=["a"])
    np.testing.assert_array_equal(s.bins, [0, 1])  # bin 2 only has w == 0
    np.testing.assert_array_equal(s.count, [3, 2])
    np.testing.assert_allclose(s.vweight["a"], [1.5, 0.0])
    df = s.finalize(0.25)
    np.testing.assert_allclose(df["a"], [(1.0 + 0.5 * 4.0) / 1.5, np.nan])
    np.testing.assert_allclose(df["b"], [(2.0 + 1.0 + 5.0) / 2.5, 2.0])
    np.testing.assert_allclose(df["a_rms"], [np.sqrt((1.0 + 0.5 * 16.0) / 1.5), np.nan])
    np.testing.assert_array_equal(df["n_samples"], [2, 2])  # round(sum w) = round(2.5) -> 2


def test_npz_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    track, values = _samples(rng, 3_000)
    s = BinSums.from_samples(position_to_bin(track), np.ones(track.size), values, squares=["amp"])
    path = tmp_path / "chunk.npz"
    np.savez(path, **s.to_arrays())
    with np.load(path) as z:
        back = BinSums.from_arrays(z)
    _assert_same(back, s)
    pd.testing.assert_frame_equal(back.finalize(0.25), s.finalize(0.25))


def test_empty_input_and_validation() -> None:
    empty = BinSums.from_samples(np.array([], dtype=np.int64), np.array([]), {"x": np.array([])})
    assert len(empty) == 0 and empty.names == ["x"]
    full = BinSums.from_samples(np.array([3, 4]), np.ones(2), {"x": np.array([1.0, 2.0])})
    _assert_same(empty.merge(full), full)
    with pytest.raises(ValueError, match="weight"):
        BinSums.from_samples(np.array([0]), np.array([-1.0]), {"x": np.array([1.0])})
    with pytest.raises(ValueError, match="bins"):
        BinSums.from_samples(np.array([0.5]), np.array([1.0]), {"x": np.array([1.0])})
    with pytest.raises(ValueError, match=r"values\['x'\]"):
        BinSums.from_samples(np.array([0]), np.array([1.0]), {"x": np.array([1.0, 2.0])})
    with pytest.raises(ValueError, match="squares"):
        BinSums.from_samples(np.array([0]), np.array([1.0]), {"x": np.array([1.0])}, squares=["y"])
    other = BinSums.from_samples(np.array([0]), np.array([1.0]), {"y": np.array([1.0])})
    with pytest.raises(ValueError, match="parts"):
        full.merge(other)
    with pytest.raises(ValueError, match="parts"):
        BinSums.merge_all([])
    with pytest.raises(ValueError, match="binsums_version"):
        BinSums.from_arrays({"bins": np.array([0])})
