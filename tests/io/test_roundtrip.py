"""simulate → export to HDF5/CSV/Parquet → ingest → open_run gives the same data."""

from __future__ import annotations

import gzip
import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest

from app.io import ALL_CHANNELS, IngestLimits, ingest, open_run, write_run_hdf5
from app.simulate.run import simulate_run
from app.simulate.speed import SpeedProfile
from tests.io.conftest import base_meta, kinematic_arrays, listing

FS_SIM = 4000.0


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """A short simulated run (accelerating, 3 s at 4 kHz) and its data."""
    d = tmp_path_factory.mktemp("sim")
    profile = SpeedProfile.from_segments(25.0, [(3.0, 28.0)])
    truth = simulate_run(d / "run.h5", duration_s=3.0, fs=FS_SIM, seed=3, speed_profile=profile)
    with open_run(truth.run_path) as run:
        data = {c: run.read(c) for c in run.channels}
        meta = json.loads(run.metadata.to_json())
    return {"path": truth.run_path, "data": data, "meta": meta, "truth": truth}


def _check_same(dest: Path, data: dict[str, np.ndarray]) -> None:
    with open_run(dest) as run:
        assert run.fs == FS_SIM
        assert run.n_samples == len(data["Z11"])
        assert set(run.channels) == set(data)
        for c, ref in data.items():
            got = run.read(c)
            if c in ("speed", "position"):
                np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9, err_msg=c)
            else:  # float32 storage: exact after the float32 round trip
                np.testing.assert_array_equal(
                    got, ref.astype(np.float32).astype(np.float64), err_msg=c
                )


def test_canonical_hdf5_reingest_without_metadata(sim: dict, out_dir: Path) -> None:
    summary = ingest(sim["path"], None, None, out_dir / "r.h5")
    assert summary.source_format == "hdf5"
    assert summary.channels == list(ALL_CHANNELS)
    assert summary.metadata.vehicle_id == "SIM-1"
    assert summary.metadata.calibration == {}  # identity gain/offset attributes are not copied
    assert summary.metadata.wheel_diameters == sim["truth"].reported_diameters
    assert summary.distance_m == pytest.approx(sim["truth"].distance_m, abs=1e-9)
    assert summary.speed_min == pytest.approx(25.0) and summary.speed_max == pytest.approx(28.0)
    assert summary.duration_s == pytest.approx(3.0)
    _check_same(out_dir / "r.h5", sim["data"])
    assert listing(out_dir) == ["r.h5"]  # no temporary file left


@pytest.mark.parametrize("kind", ["csv", "csv.gz", "parquet"])
def test_tabular_round_trip(sim: dict, tmp_path: Path, out_dir: Path, kind: str) -> None:
    df = pd.DataFrame(sim["data"])
    if kind == "parquet":
        src = tmp_path / "run.parquet"
        df.to_parquet(src, row_group_size=5000)
    else:
        src = tmp_path / "run.csv"
        df.to_csv(src, index=False, float_format="%.17g")
        if kind == "csv.gz":
            with open(src, "rb") as fi, gzip.open(tmp_path / "upload", "wb") as fo:
                shutil.copyfileobj(fi, fo)
            src = tmp_path / "upload"  # no suffix: detected from the gzip magic
    meta = {**sim["meta"], "sample_rate_hz": FS_SIM}
    summary = ingest(src, None, meta, out_dir / "r.h5", IngestLimits(block_samples=4096))
    assert summary.source_format == ("parquet" if kind == "parquet" else "csv")
    assert summary.n_samples == len(df)
    _check_same(out_dir / "r.h5", sim["data"])


def test_csv_time_column_gives_sample_rate_and_is_not_stored(tmp_path: Path, out_dir: Path) -> None:
    arrays = kinematic_arrays(3000)
    df = pd.DataFrame(
        {"time": np.arange(3000) / 2000.0 + 5.0, "z11": arrays["Z11"], "Speed": arrays["speed"]}
    )
    df.to_csv(tmp_path / "r.csv", index=False, sep=";")
    summary = ingest(tmp_path / "r.csv", "csv", base_meta(), out_dir / "r.h5")
    assert summary.fs == 2000.0
    assert summary.channels == ["Z11", "speed", "position"]  # names matched case-insensitively
    with h5py.File(out_dir / "r.h5") as h5:
        assert "time" not in h5
        assert h5.attrs["sample_rate_hz"] == 2000.0


def test_calibration_is_stored_and_applied_at_read(tmp_path: Path, out_dir: Path) -> None:
    arrays = kinematic_arrays(4000)
    counts = np.round(arrays["Z11"] * 1000.0 + 200.0)  # ADC counts
    gain, offset = 1e-3, -0.2
    pd.DataFrame({"Z11": counts, "speed": arrays["speed"]}).to_csv(tmp_path / "r.csv", index=False)
    meta = base_meta(sample_rate_hz=2000, calibration={"Z11": {"gain": gain, "offset": offset}})
    ingest(tmp_path / "r.csv", None, meta, out_dir / "r.h5")
    with h5py.File(out_dir / "r.h5") as h5:
        np.testing.assert_array_equal(h5["Z11"][()], counts.astype(np.float32))  # not baked in
        assert (h5["Z11"].attrs["gain"], h5["Z11"].attrs["offset"]) == (gain, offset)
        assert h5["speed"].attrs["gain"] == 1.0
    with open_run(out_dir / "r.h5") as run:
        np.testing.assert_allclose(
            run.read("Z11", 10, 20), gain * counts[10:20] + offset, rtol=1e-12
        )
        assert run.calibration("Z11") == (gain, offset)
        assert (
            run.metadata.calibration["Z11"].gain == gain == run.metadata.calibration["Z11"]["gain"]
        )


def test_hdf5_calibration_attributes_are_honoured_and_metadata_wins(
    tmp_path: Path, out_dir: Path
) -> None:
    arrays = kinematic_arrays(3000)
    src = tmp_path / "in.h5"
    with h5py.File(src, "w") as h5:
        h5["Z11"] = arrays["Z11"] * 100.0
        h5["Z11"].attrs["gain"] = 0.01
        h5["Z42"] = arrays["Z42"]
        h5["Z42"].attrs["gain"] = 5.0
        h5["speed"] = arrays["speed"]
        h5["speed"].attrs["units"] = "m/s"
        h5.attrs["sample_rate_hz"] = 2000.0
    meta = base_meta(calibration={"Z42": {"gain": 2.0, "offset": 0.0}})
    ingest(src, "hdf5", meta, out_dir / "r.h5")
    with open_run(out_dir / "r.h5") as run:
        np.testing.assert_allclose(run.read("Z11"), arrays["Z11"], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(run.read("Z42"), 2.0 * arrays["Z42"], rtol=1e-6, atol=1e-6)


def test_nan_gaps_are_interpolated_across_blocks(tmp_path: Path, out_dir: Path) -> None:
    n = 10_000
    t = np.arange(n) / 2000.0
    ramp = 3.0 * t + 1.0  # linear: interpolation must reproduce it exactly
    z = ramp.copy()
    z[:7] = np.nan  # leading gap → first valid value
    z[1000:1030] = np.nan  # inside a block
    z[2040:2060] = np.nan  # across the 2048-sample block boundary
    z[4090:4100] = np.nan  # across a boundary, ending just after it
    z[-3:] = np.nan  # trailing gap → last valid value
    speed = np.full(n, 20.0)
    speed[5000:5010] = np.nan
    pd.DataFrame({"Z11": z, "speed": speed}).to_csv(tmp_path / "r.csv", index=False)
    summary = ingest(
        tmp_path / "r.csv",
        None,
        base_meta(sample_rate_hz=2000),
        out_dir / "r.h5",
        IngestLimits(block_samples=2048),
    )
    assert summary.nan_filled == {"Z11": 70, "speed": 10}
    with open_run(out_dir / "r.h5") as run:
        got = run.read("Z11")
        expect = ramp.copy()
        expect[:7] = ramp[7]
        expect[-3:] = ramp[-4]
        np.testing.assert_allclose(got, expect.astype(np.float32), rtol=1e-6)
        np.testing.assert_array_equal(run.speed(), 20.0)


def test_position_derived_from_speed_is_consistent(tmp_path: Path, out_dir: Path) -> None:
    n = 150_000  # more than two POSITION_BLOCKs
    fs = 1000.0
    t = np.arange(n) / fs
    v = 20.0 + 5.0 * np.sin(2 * np.pi * t / 60.0)
    write_run_hdf5(tmp_path / "in.h5", {"Z11": np.zeros(n), "speed": v}, fs, base_meta())
    summary = ingest(tmp_path / "in.h5", None, None, out_dir / "r.h5")
    exact = 20.0 * t + 5.0 * 60.0 / (2 * np.pi) * (1 - np.cos(2 * np.pi * t / 60.0))
    with open_run(out_dir / "r.h5") as run, open_run(tmp_path / "in.h5") as raw:
        assert run.has("position") and not raw.has("position")
        full = run.position()
        np.testing.assert_allclose(full, exact, atol=1e-6)
        assert summary.distance_m == pytest.approx(exact[-1], abs=1e-6)
        # on-the-fly integration of a file without position gives the same numbers, in any slice
        np.testing.assert_array_equal(raw.position(), full)
        for a, b in [(0, 10), (65_530, 65_545), (131_000, 149_999), (70_000, 70_000)]:
            np.testing.assert_array_equal(raw.position(a, b), full[a:b])


def test_speed_derived_from_position(tmp_path: Path, out_dir: Path) -> None:
    arrays = kinematic_arrays(8000)
    write_run_hdf5(
        tmp_path / "in.h5",
        {"Z11": arrays["Z11"], "position": arrays["position"]},
        2000.0,
        base_meta(),
    )
    summary = ingest(tmp_path / "in.h5", None, None, out_dir / "r.h5")
    h = 200  # half window at 2 kHz
    with open_run(out_dir / "r.h5") as run, open_run(tmp_path / "in.h5") as raw:
        v = run.speed()
        # centred difference is exact for a quadratic position; one-sided near the ends
        np.testing.assert_allclose(v[h:-h], arrays["speed"][h:-h], atol=1e-9)
        assert np.max(np.abs(v - arrays["speed"])) < 0.5 * 0.1  # acc * window / 2
        np.testing.assert_array_equal(raw.speed(1234, 5678), v[1234:5678])
        np.testing.assert_allclose(run.position(), arrays["position"] - 100.0, atol=1e-9)
    assert summary.distance_m == pytest.approx(arrays["position"][-1] - 100.0)
    assert summary.speed_min == pytest.approx(v.min())
