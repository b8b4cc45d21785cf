"""Crafted HDF5 inputs: links and storage that could reach outside the file are rejected."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from app.io import RunFileError, ingest, open_run, write_run_hdf5
from tests.io.conftest import base_meta, kinematic_arrays, listing

N = 3000
META = base_meta(sample_rate_hz=2000)


def _base(path: Path) -> h5py.File:
    a = kinematic_arrays(N)
    h5 = h5py.File(path, "w")
    h5["Z11"] = a["Z11"]
    h5["speed"] = a["speed"]
    return h5


def _expect_rejected(src: Path, out_dir: Path, field: str, words: str) -> None:
    with pytest.raises(RunFileError) as info:
        ingest(src, None, META, out_dir / "r.h5")
    assert info.value.field == field, str(info.value)
    assert words in info.value.message, str(info.value)
    assert listing(out_dir) == []


def test_external_link_is_rejected(tmp_path: Path, out_dir: Path) -> None:
    secret = tmp_path / "secret.h5"
    with h5py.File(secret, "w") as h5:
        h5["data"] = np.arange(N, dtype=float)
    with _base(tmp_path / "in.h5") as h5:
        h5["Z12"] = h5py.ExternalLink(str(secret), "/data")
    _expect_rejected(tmp_path / "in.h5", out_dir, "Z12", "external link")


def test_soft_link_inside_the_file_is_accepted(tmp_path: Path, out_dir: Path) -> None:
    with _base(tmp_path / "in.h5") as h5:
        h5["Z12"] = h5py.SoftLink("/Z11")
    ingest(tmp_path / "in.h5", None, META, out_dir / "r.h5")
    with open_run(out_dir / "r.h5") as run:
        np.testing.assert_array_equal(run.read("Z12"), run.read("Z11"))


@pytest.mark.parametrize("target", ["/nowhere", "/Z41/../Z11"])
def test_dangling_or_escaping_soft_link_is_rejected(
    tmp_path: Path, out_dir: Path, target: str
) -> None:
    with _base(tmp_path / "in.h5") as h5:
        h5["Z12"] = h5py.SoftLink(target)
    _expect_rejected(tmp_path / "in.h5", out_dir, "Z12", "soft link")


def test_soft_link_through_an_external_link_is_rejected(tmp_path: Path, out_dir: Path) -> None:
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as h5:
        h5["data"] = np.arange(N, dtype=float)
    with _base(tmp_path / "in.h5") as h5:
        h5["Z12"] = h5py.SoftLink("/Z42")
        h5["Z42"] = h5py.ExternalLink(str(other), "/data")
    _expect_rejected(tmp_path / "in.h5", out_dir, "Z12", "inside this file")


def test_group_at_root_is_rejected(tmp_path: Path, out_dir: Path) -> None:
    with _base(tmp_path / "in.h5") as h5:
        h5.create_group("Z12")
    _expect_rejected(tmp_path / "in.h5", out_dir, "Z12", "group")


def test_virtual_dataset_is_rejected(tmp_path: Path, out_dir: Path) -> None:
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as h5:
        h5["data"] = np.arange(N, dtype=float)
    layout = h5py.VirtualLayout(shape=(N,), dtype="f8")
    layout[:] = h5py.VirtualSource(str(other), "data", shape=(N,))
    with _base(tmp_path / "in.h5") as h5:
        h5.create_virtual_dataset("Z12", layout)
    _expect_rejected(tmp_path / "in.h5", out_dir, "Z12", "virtual")


def test_external_storage_is_rejected(tmp_path: Path, out_dir: Path) -> None:
    raw = tmp_path / "raw.bin"
    np.arange(N, dtype="<f8").tofile(raw)
    with _base(tmp_path / "in.h5") as h5:
        h5.create_dataset("Z12", shape=(N,), dtype="<f8", external=[(str(raw), 0, N * 8)])
    _expect_rejected(tmp_path / "in.h5", out_dir, "Z12", "external storage")


def test_open_run_applies_the_same_checks(tmp_path: Path) -> None:
    a = kinematic_arrays(N)
    path = write_run_hdf5(tmp_path / "run.h5", {"Z11": a["Z11"], "speed": a["speed"]}, 2000.0, META)
    with h5py.File(path, "a") as h5:
        h5["Z12"] = h5py.ExternalLink(str(tmp_path / "x.h5"), "/data")
    with pytest.raises(RunFileError) as info:
        open_run(path)
    assert info.value.field == "Z12"
