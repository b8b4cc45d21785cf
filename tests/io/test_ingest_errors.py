"""Every bad input raises RunFileError naming the problem and leaves nothing at dest."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest

from app.io import IngestLimits, RunFileError, ingest
from tests.io.conftest import base_meta, kinematic_arrays, listing

N = 4000
META = base_meta(sample_rate_hz=2000)


def _csv(tmp: Path, data: dict, name: str = "r.csv") -> Path:
    pd.DataFrame(data).to_csv(tmp / name, index=False)
    return tmp / name


def _h5(tmp: Path, data: dict, attrs: dict | None = None) -> Path:
    with h5py.File(tmp / "r.h5", "w") as h5:
        for k, v in data.items():
            h5[k] = v
        for k, v in (attrs or {}).items():
            h5.attrs[k] = v
    return tmp / "r.h5"


def _good() -> dict:
    a = kinematic_arrays(N)
    return {"Z11": a["Z11"], "speed": a["speed"], "position": a["position"]}


def _with(**changes: np.ndarray | None) -> dict:
    data = _good()
    for k, v in changes.items():
        if v is None:
            data.pop(k)
        else:
            data[k] = v
    return data


def _nan_z(frac: float) -> np.ndarray:
    z = _good()["Z11"].copy()
    z[100 : 100 + int(frac * N)] = np.nan
    return z


def _bad_position() -> np.ndarray:
    p = _good()["position"].copy()
    p[2500] = p[2499] - 0.5
    return p


def _kmh() -> np.ndarray:
    return _good()["speed"] * 3.6 + 100  # > 100 "m/s"


Case = tuple[str, Callable[[Path], Path], dict | None, str | None, str, str]

CASES: list[Case] = [
    # id, make(tmp) -> src, metadata, fmt, field, words in message
    (
        "unknown-format",
        lambda t: (t / "r.bin").write_bytes(bytes(range(256)) * 4) and t / "r.bin",
        META,
        None,
        "format",
        "unknown format",
    ),
    (
        "declared-format-mismatch",
        lambda t: _csv(t, _good()),
        META,
        "hdf5",
        "format",
        "HDF5 signature",
    ),
    (
        "declared-format-unknown",
        lambda t: _csv(t, _good()),
        META,
        "xlsx",
        "format",
        "unknown format",
    ),
    (
        "empty-file",
        lambda t: (t / "r.csv").write_bytes(b"") or t / "r.csv",
        META,
        None,
        "file",
        "empty",
    ),
    (
        "no-samples",
        lambda t: (t / "r.csv").write_text("Z11,speed\n") and t / "r.csv",
        META,
        None,
        "file",
        "no samples",
    ),
    ("missing-z", lambda t: _csv(t, _with(Z11=None)), META, None, "Z11", "missing channel"),
    (
        "missing-speed-and-position",
        lambda t: _csv(t, _with(speed=None, position=None)),
        META,
        None,
        "speed",
        "speed or position",
    ),
    (
        "unknown-channel",
        lambda t: _csv(t, {**_good(), "Z13": _good()["Z11"]}),
        META,
        None,
        "Z13",
        "unknown channel",
    ),
    (
        "duplicate-channel",
        lambda t: (t / "r.csv").write_text("Z11,z11,speed\n1,2,3\n") and t / "r.csv",
        META,
        None,
        "z11",
        "duplicate",
    ),
    (
        "non-numeric-csv",
        lambda t: _csv(t, _with(Z11=np.array(["1.5"] * (N - 1) + ["abc"], dtype=object))),
        META,
        None,
        "Z11",
        "non-numeric",
    ),
    (
        "non-monotonic-position",
        lambda t: _csv(t, _with(position=_bad_position())),
        META,
        None,
        "position",
        "non-monotonic",
    ),
    ("too-many-nan", lambda t: _csv(t, _with(Z11=_nan_z(0.02))), META, None, "Z11", "too many NaN"),
    (
        "all-nan",
        lambda t: _csv(t, _with(Z11=np.full(N, np.nan))),
        META,
        None,
        "Z11",
        "too many NaN",
    ),
    (
        "infinite",
        lambda t: _csv(t, _with(Z11=np.where(np.arange(N) == 7, np.inf, 1.0))),
        META,
        None,
        "Z11",
        "infinite",
    ),
    (
        "speed-in-kmh",
        lambda t: _csv(t, _with(speed=_kmh(), position=None)),
        META,
        None,
        "speed",
        "m/s",
    ),
    (
        "negative-speed",
        lambda t: _csv(t, _with(speed=np.full(N, -3.0), position=None)),
        META,
        None,
        "speed",
        "negative",
    ),
    (
        "speed-position-disagree",
        lambda t: _csv(t, _with(speed=_good()["speed"] * 2)),
        META,
        None,
        "speed",
        "integrated speed",
    ),
    (
        "sample-rate-missing",
        lambda t: _csv(t, _good()),
        base_meta(),
        None,
        "sample_rate_hz",
        "missing",
    ),
    (
        "sample-rate-too-low",
        lambda t: _csv(t, _good()),
        base_meta(sample_rate_hz=500),
        None,
        "sample_rate_hz",
        "invalid sample rate",
    ),
    (
        "sample-rate-vs-time",
        lambda t: _csv(t, {**_good(), "time": np.arange(N) / 1000.0}),
        META,
        None,
        "sample_rate_hz",
        "disagrees",
    ),
    (
        "time-not-uniform",
        lambda t: _csv(
            t, {**_good(), "time": np.r_[np.arange(N // 2), np.arange(N // 2) + N] / 2000.0}
        ),
        base_meta(),
        None,
        "time",
        "uniform grid",
    ),
    ("metadata-missing", lambda t: _csv(t, _good()), None, None, "metadata", "required"),
    (
        "metadata-naive-time",
        lambda t: _csv(t, _good()),
        {**META, "start_time": "2024-05-01T08:00:00"},
        None,
        "start_time",
        "time zone",
    ),
    (
        "metadata-unknown-field",
        lambda t: _csv(t, _good()),
        {**META, "wagon": 3},
        None,
        "wagon",
        "unknown metadata field",
    ),
    (
        "metadata-bad-value",
        lambda t: _csv(t, _good()),
        {**META, "sleeper_spacing": "wide"},
        None,
        "sleeper_spacing",
        "",
    ),
    (
        "hdf5-unequal-length",
        lambda t: _h5(t, _with(Z11=np.zeros(N - 1))),
        META,
        None,
        "Z11",
        "unequal length",
    ),
    (
        "hdf5-string-dataset",
        lambda t: _h5(t, _with(Z11=np.array(["a"] * N, dtype="S1"))),
        META,
        None,
        "Z11",
        "wrong dtype",
    ),
    (
        "hdf5-bool-dataset",
        lambda t: _h5(t, _with(Z11=np.zeros(N, dtype=bool))),
        META,
        None,
        "Z11",
        "wrong dtype",
    ),
    ("hdf5-2d-dataset", lambda t: _h5(t, _with(Z11=np.zeros((N, 2)))), META, None, "Z11", "1-D"),
    (
        "hdf5-empty",
        lambda t: _h5(t, {k: v[:0] for k, v in _good().items()}),
        META,
        None,
        "file",
        "no samples",
    ),
    (
        "hdf5-fs-attr-conflict",
        lambda t: _h5(t, _good(), {"sample_rate_hz": 4000.0}),
        META,
        None,
        "sample_rate_hz",
        "attribute",
    ),
    ("hdf5-bad-units", lambda t: _units(t), META, None, "Z11", "units"),
    (
        "hdf5-bad-metadata-attr",
        lambda t: _h5(t, _good(), {"metadata": "{not json"}),
        None,
        None,
        "metadata",
        "JSON",
    ),
    ("hdf5-corrupt", lambda t: _corrupt(t), META, None, "file", "HDF5"),
    (
        "parquet-string-column",
        lambda t: _parquet(t, _with(Z11=np.array(["x"] * N, dtype=object))),
        META,
        None,
        "Z11",
        "wrong dtype",
    ),
]


def _units(t: Path) -> Path:
    p = _h5(t, _good())
    with h5py.File(p, "a") as h5:
        h5["Z11"].attrs["units"] = "g"
    return p


def _corrupt(t: Path) -> Path:
    p = _h5(t, _good())
    raw = bytearray(p.read_bytes())
    raw[8:200] = b"\xff" * 192  # keep the signature, break the superblock
    p.write_bytes(bytes(raw))
    return p


def _parquet(t: Path, data: dict) -> Path:
    pd.DataFrame(data).to_parquet(t / "r.parquet")
    return t / "r.parquet"


@pytest.mark.parametrize(
    ("make", "meta", "fmt", "field", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_bad_input(
    tmp_path: Path,
    out_dir: Path,
    make: Callable[[Path], Path],
    meta: dict | None,
    fmt: str | None,
    field: str,
    words: str,
) -> None:
    src = make(tmp_path)
    dest = out_dir / "run.h5"
    with pytest.raises(RunFileError) as info:
        ingest(src, fmt, meta, dest, IngestLimits(block_samples=1024))
    assert info.value.field == field, str(info.value)
    assert words in info.value.message, str(info.value)
    assert listing(out_dir) == []  # nothing at dest, no temporary file


def test_good_input_of_the_cases_is_accepted(tmp_path: Path, out_dir: Path) -> None:
    """The cases above differ from this accepted file only in the one defect."""
    summary = ingest(
        _csv(tmp_path, _good()), None, META, out_dir / "run.h5", IngestLimits(block_samples=1024)
    )
    assert summary.n_samples == N
    ok = _nan_z(0.009)  # below the 1 % limit
    summary = ingest(_csv(tmp_path, _with(Z11=ok), "b.csv"), None, META, out_dir / "b.h5")
    assert summary.nan_filled == {"Z11": int(0.009 * N)}


def test_nan_limit_is_configurable(tmp_path: Path, out_dir: Path) -> None:
    src = _csv(tmp_path, _with(Z11=_nan_z(0.02)))
    summary = ingest(src, None, META, out_dir / "run.h5", IngestLimits(max_nan_fraction=0.05))
    assert summary.nan_filled == {"Z11": int(0.02 * N)}


def test_existing_dest_is_untouched_on_error(tmp_path: Path, out_dir: Path) -> None:
    dest = out_dir / "run.h5"
    dest.write_bytes(b"previous")
    with pytest.raises(RunFileError):
        ingest(_csv(tmp_path, _with(position=_bad_position())), None, META, dest)
    assert dest.read_bytes() == b"previous"
    assert listing(out_dir) == ["run.h5"]


def test_missing_source_and_bad_limits(tmp_path: Path, out_dir: Path) -> None:
    with pytest.raises(RunFileError) as info:
        ingest(tmp_path / "nope.csv", None, META, out_dir / "r.h5")
    assert info.value.field == "file"
    with pytest.raises(TypeError):
        ingest(
            _csv(tmp_path, _good()), None, META, out_dir / "r.h5", limits={"max_nan_fraction": 0.5}
        )  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="max_nan_fraction"):
        IngestLimits(max_nan_fraction=1.5)
    assert listing(out_dir) == []
