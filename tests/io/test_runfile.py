"""RunFile: reading, slicing, km and track positions, format checks."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from app.io import RunFileError, open_run, write_run_hdf5
from tests.io.conftest import base_meta, kinematic_arrays

N = 5000


@pytest.fixture
def run_path(tmp_path: Path) -> Path:
    a = kinematic_arrays(N)
    return write_run_hdf5(
        tmp_path / "run.h5",
        {
            "Z11": a["Z11"],
            "Q11": 80.0 + 0.3 * a["Z11"],
            "speed": a["speed"],
            "position": a["position"],
        },
        2000.0,
        base_meta(km_start=25.0, axle_positions={"4": -17.5}),
        calibration={"Q11": {"gain": 2.0, "offset": 1.0}},
    )


def test_basic_properties_and_read(run_path: Path) -> None:
    a = kinematic_arrays(N)
    with open_run(run_path) as run:
        assert run.fs == 2000.0 and run.n_samples == N and run.duration_s == 2.5
        assert run.channels == ("Z11", "Q11", "speed", "position")
        assert run.has("Q11") and not run.has("Z12")
        np.testing.assert_array_equal(run.read("Z11", 10, 20), a["Z11"][10:20].astype(np.float32))
        q = run.read("Q11")
        assert q.dtype == np.float64
        np.testing.assert_allclose(q, 2.0 * (80.0 + 0.3 * a["Z11"]) + 1.0, rtol=1e-6)
        np.testing.assert_allclose(run.time(0, 3), [0.0, 0.0005, 0.001])
        assert run.read("Z11", 7, 7).size == 0
    assert not run._h5.id.valid  # closed by the context manager


def test_km_and_track_position_per_axle(run_path: Path, tmp_path: Path) -> None:
    a = kinematic_arrays(N)
    rel = a["position"] - a["position"][0]
    with open_run(run_path) as run:
        np.testing.assert_allclose(run.position(), rel, atol=1e-9)
        np.testing.assert_allclose(run.km(axle="1"), 25.0 + rel / 1000.0, atol=1e-12)
        np.testing.assert_allclose(
            run.km(100, 200, axle="4"), 25.0 + (rel[100:200] - 17.5) / 1000.0, atol=1e-12
        )
        np.testing.assert_allclose(run.track_m(axle="4"), 25_000.0 + rel - 17.5, atol=1e-9)
        with pytest.raises(ValueError, match="axle"):
            run.km(axle="2")
    down = write_run_hdf5(
        tmp_path / "down.h5",
        {"Z11": a["Z11"], "speed": a["speed"]},
        2000.0,
        base_meta(km_increasing=False),
    )
    with open_run(down) as run:
        pos = run.position()
        np.testing.assert_allclose(run.km(axle="4"), 10.0 - (pos - 17.5) / 1000.0, atol=1e-12)
        assert run.km()[-1] < run.km()[0]


def test_bad_arguments(run_path: Path) -> None:
    with open_run(run_path) as run:
        with pytest.raises(ValueError, match="name"):
            run.read("Z12")
        with pytest.raises(ValueError, match="start/stop"):
            run.read("Z11", 10, 5)
        with pytest.raises(ValueError, match="start/stop"):
            run.read("Z11", 0, N + 1)
        with pytest.raises(ValueError, match="start/stop"):
            run.read("Z11", -1, 5)


def test_not_a_run_file(tmp_path: Path) -> None:
    (tmp_path / "x.csv").write_text("Z11,speed\n1,2\n")
    with pytest.raises(RunFileError) as info:
        open_run(tmp_path / "x.csv")
    assert info.value.field == "format"
    with h5py.File(tmp_path / "plain.h5", "w") as h5:
        h5["Z11"] = np.zeros(3)
    with pytest.raises(RunFileError) as info:
        open_run(tmp_path / "plain.h5")
    assert info.value.field == "format"


def test_write_run_hdf5_validates(tmp_path: Path) -> None:
    with pytest.raises(RunFileError) as info:
        write_run_hdf5(
            tmp_path / "r.h5", {"Z11": np.zeros(3), "speed": np.zeros(4)}, 1000.0, base_meta()
        )
    assert "unequal length" in info.value.message
    with pytest.raises(RunFileError) as info:
        write_run_hdf5(tmp_path / "r.h5", {"Z99": np.zeros(3)}, 1000.0, base_meta())
    assert info.value.field == "Z99"
    with pytest.raises(RunFileError) as info:
        write_run_hdf5(tmp_path / "r.h5", {"Z11": np.zeros(3)}, 0.0, base_meta())
    assert info.value.field == "sample_rate_hz"
    assert list(tmp_path.iterdir()) == []


def test_layout_attributes(run_path: Path) -> None:
    with h5py.File(run_path) as h5:
        assert h5.attrs["trackvkf_format_version"] == 1
        assert h5.attrs["n_samples"] == N
        assert h5["Z11"].dtype == np.float32 and h5["position"].dtype == np.float64
        assert h5["Z11"].attrs["units"] == "m/s^2" and h5["Q11"].attrs["units"] == "kN"
        assert h5["Q11"].attrs["gain"] == 2.0 and h5["Q11"].attrs["offset"] == 1.0
        # "auto" compression: measurement channels plain (fast reads), kinematics LZF
        assert h5["Z11"].compression is None and h5["Z11"].chunks is not None
        assert h5["position"].compression == "lzf" and h5["position"].shuffle
