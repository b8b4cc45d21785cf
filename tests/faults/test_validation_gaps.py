"""Issue 18 item 7: values that were accepted at upload and failed (or lied) later.

A 50 MB HDF5 ``metadata`` attribute was stored (GET /runs/7 answered 50 MB);
a 1-row CSV and a calibration gain of 1e308 were accepted and then failed in
the worker; ``km_increasing: "yes"`` was taken as true; ``line_id: 1e400`` was
stored as "inf". Each is refused at upload now, naming the field.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from app.io import RunFileError, ingest
from tests.api import runfiles
from tests.api.support import store_files
from tests.faults.support import hdf5_run, last_upload_audit, upload_csv, upload_file


def _rejected(client, response, field: str) -> str:
    assert response.status_code == 422, response.text
    body = response.json()
    assert body["field"] == field, body
    assert last_upload_audit(client)["outcome"] == "rejected"
    assert store_files(client.settings.run_store) == []
    return body["detail"]


@pytest.mark.parametrize("mb", [2, 50])
def test_large_hdf5_metadata_attribute(client, tmp_path, mb):
    path = hdf5_run(tmp_path)
    md = runfiles.metadata(sample_rate_hz=None, extra={"padding": "x" * (mb << 20)})
    with h5py.File(path, "r+") as h5:
        h5.attrs["metadata"] = json.dumps(md)
    detail = _rejected(client, upload_file(client, path), "metadata")
    assert "bytes" in detail and len(detail) < 400


def test_large_hdf5_attribute_of_fixed_length_is_refused_before_reading(tmp_path):
    path = tmp_path / "units.h5"
    with h5py.File(path, "w", libver="latest") as h5:  # dense attribute storage: no 64 KiB limit
        for name, values in runfiles.channels().items():
            h5[name] = values
        h5["Z11"].attrs["units"] = np.bytes_(b"m/s^2" + b" " * (4 << 20))
    with pytest.raises(RunFileError) as err:
        ingest(path, "hdf5", None, tmp_path / "out.h5")
    assert err.value.field == "Z11.units"


def test_one_row_csv(client, tmp_path):
    path = tmp_path / "one.csv"
    path.write_text("Z11,Z12,Z41,Z42,speed,position\n0.1,0.2,0.3,0.4,20,0\n")
    detail = _rejected(client, upload_file(client, path, json.dumps(runfiles.metadata()), "text/csv"), "file")
    assert "1 s" in detail or "second" in detail


def test_run_shorter_than_a_second(client, tmp_path):
    r = upload_file(
        client,
        runfiles.write_csv(tmp_path / "short.csv", runfiles.channels(n=int(runfiles.FS) - 1)),
        json.dumps(runfiles.metadata()),
        "text/csv",
    )
    _rejected(client, r, "file")


@pytest.mark.parametrize(
    ("calibration", "field"),
    [
        ({"Z11": {"gain": 1e308}}, "calibration.Z11"),
        ({"Z12": {"offset": 1e300}}, "calibration.Z12"),
        ({"position": {"gain": 1e300}}, "calibration.position"),
    ],
)
def test_calibration_that_overflows_the_physical_values(client, tmp_path, calibration, field):
    detail = _rejected(client, upload_csv(client, tmp_path, calibration=calibration), field)
    assert "calibration" in detail


def test_raw_values_beyond_float32_are_refused(tmp_path):
    data = runfiles.channels()
    data["Z11"] = data["Z11"].astype(np.float64)
    data["Z11"][7] = 1e39
    path = runfiles.write_csv(tmp_path / "f32.csv", data)
    md = runfiles.metadata(calibration={"Z11": {"gain": 1e-40}})
    with pytest.raises(RunFileError) as err:
        ingest(path, "csv", md, tmp_path / "out.h5")
    assert err.value.field == "Z11"
    assert "sample 7" in err.value.message


@pytest.mark.parametrize("value", ["yes", "true", 1, "1", "on"])
def test_km_increasing_must_be_a_json_boolean(client, tmp_path, value):
    detail = _rejected(client, upload_csv(client, tmp_path, km_increasing=value), "km_increasing")
    assert "true or false" in detail


@pytest.mark.parametrize("field", ["line_id", "vehicle_id", "track", "direction"])
def test_text_fields_given_as_infinite_numbers(client, tmp_path, field):
    text = json.dumps(runfiles.metadata(**{field: None}))[:-1] + f', "{field}": 1e400}}'
    _rejected(client, upload_csv(client, tmp_path, text), field)


def test_text_fields_given_as_numbers_still_work(client, tmp_path):
    r = upload_csv(client, tmp_path, line_id=4010, track=1)
    assert r.status_code == 201, r.text
    assert r.json()["line_id"] == "4010" and r.json()["track"] == "1"


def test_nan_and_infinity_literals_in_metadata(client, tmp_path):
    text = json.dumps(runfiles.metadata())[:-1] + ', "extra": {"x": NaN}}'
    _rejected(client, upload_csv(client, tmp_path, text), "extra.x")
    text = json.dumps(runfiles.metadata(km_start=None))[:-1] + ', "km_start": -Infinity}'
    _rejected(client, upload_csv(client, tmp_path, text), "km_start")
