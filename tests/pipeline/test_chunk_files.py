"""Chunk result files: a group of per-bin sums is packed into four ``.npz`` members and
read back exactly; files of the earlier layout (one member per array) still read."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.binning import BinSums
from app.pipeline.chunkfile import load_group, pack_group


class _Npz(dict):
    """A dict with the ``files`` attribute of ``numpy.lib.npyio.NpzFile``."""

    files = property(lambda self: list(self))


def _sums() -> BinSums:
    rng = np.random.default_rng(1)
    bins = np.sort(rng.choice(10_000, 50, replace=False)) - 3_000  # negative bins too
    return BinSums.from_samples(
        np.repeat(bins, 3), rng.random(150), {"x": rng.standard_normal(150), "y": rng.random(150)},
        squares=("x",),
    )


def _assert_same(a: BinSums, b: BinSums) -> None:
    for name in ("bins", "weight", "count"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    for name in ("sums", "sq", "vweight"):
        da, db = getattr(a, name), getattr(b, name)
        assert set(da) == set(db)
        for k in da:
            np.testing.assert_array_equal(da[k], db[k])


def test_packed_group_round_trip(tmp_path):
    sums = _sums()
    packed = pack_group("bins_11__", sums.to_arrays())
    assert len(packed) == 4
    np.savez(tmp_path / "c.npz", **packed, other=np.zeros(3))
    with np.load(tmp_path / "c.npz") as npz:
        _assert_same(load_group(npz, "bins_11__"), sums)
        assert load_group(npz, "bins_12__") is None


def test_earlier_layout_still_reads():
    sums = _sums()
    legacy = _Npz({f"resid_41__{k}": v for k, v in sums.to_arrays().items()})
    _assert_same(load_group(legacy, "resid_41__"), sums)


def test_empty_group_and_refusals():
    empty = BinSums.merge_all([_sums()])
    empty = BinSums.from_arrays({k: (v[:0] if np.ndim(v) else v) for k, v in empty.to_arrays().items()})
    back = load_group(_Npz(pack_group("g__", empty.to_arrays())), "g__")
    assert back.bins.size == 0 and set(back.sums) == {"x", "y"}
    with pytest.raises(ValueError, match="different lengths"):
        pack_group("g__", {"a": np.zeros(2), "b": np.zeros(3)})
    with pytest.raises(ValueError, match="only 1-D"):
        pack_group("g__", {"a": np.zeros((2, 2))})
