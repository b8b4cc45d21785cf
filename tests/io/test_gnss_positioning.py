"""Line geometry import and GNSS runs end to end through ingest (matching and fusion: tests/analysis)."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from app.io import RunFileError, ingest, open_run
from app.io.geometry import parse_geojson
from app.simulate.geometry import synthetic_line
from app.simulate.recorder import GnssSimulation, simulate_recorder_run
from tests.io.conftest import listing


def _doc():
    _, doc = synthetic_line(10.0, 14.0, seed=2, line_id="4010", track="1")
    return doc


def test_geojson_import_any_crs_and_errors() -> None:
    doc = _doc()
    (geom,) = parse_geojson(doc)
    assert geom.source_crs.endswith("25832") and abs(geom.length_m - 4000.0) < 5.0
    lon, lat = geom.lonlat_at_km(np.array([12.0]))
    assert 8.0 < lon[0] < 10.5 and 49.0 < lat[0] < 51.0
    wgs = copy.deepcopy(doc)
    del wgs["crs"]
    wgs["features"][0]["geometry"]["coordinates"] = [
        [float(a), float(b)] for a, b in zip(geom.lon, geom.lat, strict=True)
    ]
    (again,) = parse_geojson(wgs)
    np.testing.assert_allclose(again.lat, geom.lat, atol=1e-9)
    bad = copy.deepcopy(doc)
    del bad["features"][0]["properties"]["km"]
    with pytest.raises(RunFileError) as exc:
        parse_geojson(bad)
    assert exc.value.field == "features[0]" and "no km stations" in exc.value.message
    assert "line 4010 track 1" in exc.value.message
    metres = copy.deepcopy(doc)
    metres["features"][0]["properties"]["km"] = [k * 1000 for k in doc["features"][0]["properties"]["km"]]
    with pytest.raises(RunFileError, match="km in metres"):
        parse_geojson(metres)
    wrong = copy.deepcopy(doc)
    wrong["crs"]["properties"]["name"] = "EPSG:999999"
    with pytest.raises(RunFileError) as exc:
        parse_geojson(wrong)
    assert exc.value.field == "crs"


@pytest.fixture(scope="module")
def gnss_run(tmp_path_factory: pytest.TempPathFactory):
    d = tmp_path_factory.mktemp("gnss")
    return simulate_recorder_run(d / "run.mf4", "mdf4", gnss=GnssSimulation(), length_km=12,
                                 fs=2000.0, seed=5, with_forces=False)


def test_gnss_run_km_within_one_metre_where_gnss_is_good(gnss_run, tmp_path: Path) -> None:
    rec = gnss_run
    assert rec.outages, "the simulation has outages"
    s = ingest(rec.path, None, rec.metadata, tmp_path / "run.h5", channel_map=rec.channel_map,
               geometry=lambda line, track: rec.geometry if (line, track) == ("SIM", "1") else None)
    assert s.report["km_source"] == "gnss" and s.report["fusion"]["n_used"] > 1000
    assert any("outage" in w for w in s.warnings)
    with open_run(tmp_path / "run.h5") as run:
        k = np.arange(0, run.n_samples, 50)
        km = run.km()[k]
        assert run.metadata.position_kind == "relative"
    t = k / s.fs
    err = 1000.0 * km - rec.true_chainage_m(t)
    good = np.ones(t.size, dtype=bool)
    for a, b in rec.outages:
        good &= (t < a) | (t > b)
    assert np.abs(err[good]).max() < 1.0
    assert np.abs(err[~good]).max() < 3.0  # bridged by the odometry


def test_gnss_rejections_store_nothing(gnss_run, tmp_path: Path) -> None:
    rec = gnss_run
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    with pytest.raises(RunFileError) as exc:
        ingest(rec.path, None, rec.metadata, out_dir / "a.h5", channel_map=rec.channel_map)
    assert exc.value.field == "lat" and "line geometry of line SIM track 1" in exc.value.message
    (far,) = parse_geojson(synthetic_line(0.0, 30.0, seed=99, line_id="SIM", track="1")[1])
    with pytest.raises(RunFileError) as exc:
        ingest(rec.path, None, rec.metadata, out_dir / "b.h5", channel_map=rec.channel_map,
               geometry=far)
    assert exc.value.field == "lat" and "more than 50 m" in exc.value.message
    assert listing(out_dir) == []
