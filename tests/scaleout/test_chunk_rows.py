"""Rows stored chunk by chunk (fan-out mode): every chunk's own rows, the seam rows and
the corrected display levels together are exactly the rows of the whole wheel.

Checked on runs processed by the real pipeline (chunk files on disk) and, for the
display-level bound the correction rests on, on random profiles.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from app.analysis.aggregate import display_levels
from app.analysis.settings import ProcessingSettings
from worker.pipeline import (
    _load_group,
    _pack_group,
    assemble_wheel,
    bin_coverage,
    chunk_bin_spans,
    chunk_final_rows,
    plan_chunks,
    process_chunk,
    seam_rows,
)

SETTINGS = ProcessingSettings.from_dict({"chunk_seconds": 4.0})


def _processed(path, tmp, settings=SETTINGS):
    chunks = plan_chunks(path, settings)
    files = []
    for chunk in chunks:
        out = tmp / f"chunk-{chunk.index:05d}.npz"
        process_chunk(path, settings, chunk, out)
        files.append(out)
    return chunks, files, chunk_bin_spans(path, settings, chunks)


@pytest.fixture(scope="module")
def forward_run(tmp_path_factory):
    from app.simulate.run import simulate_run

    tmp = tmp_path_factory.mktemp("forward")
    simulate_run(tmp / "run.h5", length_km=0.3, fs=5_000.0, seed=4, with_forces=True)
    return (tmp / "run.h5", *_processed(tmp / "run.h5", tmp))


def _store_chunkwise(files, spans_by_chunk, wheel, settings=SETTINGS):
    """Emulate the fan-out tasks: chunk rows, then seam rows and level updates."""
    spans = np.array([s[wheel] for s in spans_by_chunk])
    parts = [chunk_final_rows(settings, f, {wheel: spans}, i) for i, f in enumerate(files)]
    stored = pd.concat([p for p in parts if p is not None], ignore_index=True)
    whole, _ = assemble_wheel(settings, files, wheel)
    seams, bins, levels = seam_rows(whole, spans)
    assert not set(seams["bin"]) & set(stored["bin"]), "a bin stored twice"
    stored = stored.set_index("bin")
    stored.loc[bins, "display_level"] = levels
    stored = pd.concat([stored.reset_index(), seams], ignore_index=True)
    return stored.sort_values("bin").reset_index(drop=True), whole, len(bins), len(seams)


@pytest.mark.parametrize("wheel", ["11", "12", "41", "42"])
def test_chunk_rows_and_seams_are_the_whole_wheel(forward_run, wheel):
    _, chunks, files, spans_by_chunk = forward_run
    assert len(chunks) >= 3
    stored, whole, n_changed, n_seam = _store_chunkwise(files, spans_by_chunk, wheel)
    expected = whole.assign(
        display_level=display_levels(whole["bin"].to_numpy(), whole["sleeper_amp"].to_numpy())
    )
    pd.testing.assert_frame_equal(stored[expected.columns], expected, check_exact=True)
    # most rows come from the chunks; few need the whole wheel
    assert 0 < n_seam < 0.25 * len(whole)
    assert n_changed < 0.05 * len(whole)


def test_spans_hold_every_bin_of_their_chunk(forward_run):
    _, chunks, files, spans_by_chunk = forward_run
    for i, f in enumerate(files):
        with np.load(f) as npz:
            for wheel in ("11", "41"):
                b = _load_group(npz, f"bins_{wheel}__").bins
                lo, hi = spans_by_chunk[i][wheel]
                assert b.min() >= lo and b.max() <= hi
    # neighbouring chunks share their crossfade's bins, no other
    for wheel in ("11", "41"):
        spans = np.array([s[wheel] for s in spans_by_chunk])
        assert np.all(spans[1:, 0] <= spans[:-1, 1])
        assert np.all(spans[2:, 0] > spans[:-2, 1])


def test_chunk_with_bins_outside_its_span_is_refused(forward_run):
    _, _, files, spans_by_chunk = forward_run
    spans = np.array([s["11"] for s in spans_by_chunk])
    spans[1, 1] = spans[1, 0] + 3
    with pytest.raises(ValueError, match="outside its span"):
        chunk_final_rows(SETTINGS, files[1], {"11": spans}, 1)


def test_chunk_rows_of_all_wheels_at_once(forward_run):
    _, _, files, spans_by_chunk = forward_run
    spans = {w: np.array([s[w] for s in spans_by_chunk]) for w in ("11", "12", "41", "42")}
    together = chunk_final_rows(SETTINGS, files[2], spans, 2)
    one_by_one = pd.concat([chunk_final_rows(SETTINGS, files[2], {w: sp}, 2) for w, sp in spans.items()],
                           ignore_index=True)
    pd.testing.assert_frame_equal(together, one_by_one)
    assert list(together["wheel"].unique()) == ["11", "12", "41", "42"]


def test_descending_km_run(tmp_path):
    """Track km decreasing along the run: spans still hold the chunks' bins."""
    from app.simulate.run import simulate_run

    simulate_run(tmp_path / "run.h5", length_km=0.2, fs=5_000.0, seed=5, with_forces=False,
                 km_increasing=False)
    _, files, spans_by_chunk = _processed(tmp_path / "run.h5", tmp_path)
    stored, whole, _, _ = _store_chunkwise(files, spans_by_chunk, "42")
    expected = whole.assign(
        display_level=display_levels(whole["bin"].to_numpy(), whole["sleeper_amp"].to_numpy())
    )
    pd.testing.assert_frame_equal(stored[expected.columns], expected, check_exact=True)


def test_bin_coverage_counts_overlapping_spans():
    spans = np.array([[0, 10], [8, 20], [15, 15], [30, 40]])
    bins = np.array([-1, 0, 7, 8, 10, 11, 15, 16, 25, 30, 41])
    np.testing.assert_array_equal(bin_coverage(bins, spans), [0, 1, 1, 2, 2, 1, 2, 1, 0, 1, 0])
    with pytest.raises(ValueError, match="last bin before first"):
        bin_coverage(bins, np.array([[3, 2]]))


@pytest.mark.parametrize("seed", range(30))
def test_level_over_whole_never_exceeds_level_over_part(seed):
    """Why few levels change: a bin's level over the whole profile is at most its level
    over any contiguous part that holds it, unless that is the part's top level (where
    the part's pyramid stops) or the bin is an end of the whole."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(50, 3000))
    bins = np.sort(rng.choice(5 * n, size=n, replace=False)) + int(rng.integers(-1000, 1000))
    values = rng.standard_normal(n)
    values[rng.random(n) < 0.05] = np.nan
    values[rng.random(n) < 0.1] = 0.5  # ties
    whole = display_levels(bins, values)
    cuts = np.sort(rng.choice(np.arange(1, n), size=min(5, n - 1), replace=False))
    for part in np.split(np.arange(n), cuts):
        local = display_levels(bins[part], values[part])
        below_top = (part != 0) & (part != n - 1) & (local < local.max())
        assert np.all(whole[part[below_top]] <= local[below_top])


def test_packed_group_round_trip():
    arrays = {"binsums_version": np.array(1), "bins": np.arange(5, dtype=np.int64),
              "count": np.ones(5, dtype=np.int64), "weight": np.linspace(0, 1, 5), "sum__x": np.arange(5.0),
              "vw__x": np.ones(5)}
    packed = _pack_group("g__", arrays)
    assert len(packed) == 4

    class Npz(dict):
        files = property(lambda self: list(self))

    back = _load_group(Npz(packed), "g__")
    np.testing.assert_array_equal(back.bins, arrays["bins"])
    np.testing.assert_array_equal(back.sums["x"], arrays["sum__x"])
    with pytest.raises(ValueError, match="different lengths"):
        _pack_group("g__", {"a": np.zeros(2), "b": np.zeros(3)})
