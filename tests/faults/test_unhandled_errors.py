"""Issue 18 item 2: inputs that used to raise past the API (500, no audit entry).

Metadata JSON nested 100 000 deep (form field) or 50 000 deep (HDF5
attribute) raised RecursionError; an integer of more than 4300 digits
ValueError; start times at the ends of the datetime range OverflowError; on
PostgreSQL a NUL character in ``vehicle_id`` or ``extra`` a database error.
Each must be a 4xx naming the field, with the rejection in the audit log.
"""

from __future__ import annotations

import json

import h5py
import pytest

from tests.api import runfiles
from tests.faults.support import csv_run, hdf5_run, last_upload_audit, upload_csv, upload_file


def _assert_rejected(client, response, field: str, status: int = 422) -> None:
    assert response.status_code == status, response.text
    body = response.json()
    assert body["field"] == field, body
    assert body["detail"].startswith(f"{field}: ")
    entry = last_upload_audit(client)
    assert entry["outcome"] == "rejected"
    assert entry["detail"]["field"] == field
    assert entry["detail"]["status"] == status


def _nested(depth: int) -> str:
    return "[" * depth + "]" * depth


def test_metadata_form_field_nested_100k_deep(client, tmp_path):
    md = json.dumps(runfiles.metadata())[:-1] + ', "extra": {"deep": ' + _nested(100_000) + "}}"
    _assert_rejected(client, upload_csv(client, tmp_path, md), "metadata")
    assert "nested" in client.get("/api/v1/audit", params={"limit": 1}).json()["items"][0]["detail"]["message"]


def test_metadata_nested_a_little_deeper_than_allowed(client, tmp_path):
    md = runfiles.metadata(extra={"deep": json.loads(_nested(40))})
    _assert_rejected(client, upload_csv(client, tmp_path, json.dumps(md)), "metadata")


def test_hdf5_metadata_attribute_nested_50k_deep(client, tmp_path):
    path = hdf5_run(tmp_path)
    with h5py.File(path, "r+") as h5:
        h5.attrs["metadata"] = json.dumps(runfiles.metadata(sample_rate_hz=None))[:-1] + ', "extra": ' + _nested(50_000) + "}"
    _assert_rejected(client, upload_file(client, path), "metadata")


@pytest.mark.parametrize("where", ["extra", "km_start"])
def test_integer_of_5000_digits(client, tmp_path, where):
    md = runfiles.metadata(km_start=None)
    text = json.dumps(md)[:-1]
    digits = "7" * 5000
    if where == "extra":
        text += f', "km_start": 1.0, "extra": {{"n": {digits}}}}}'
        field = "extra.n"
    else:
        text += f', "km_start": {digits}}}'
        field = "km_start"
    _assert_rejected(client, upload_csv(client, tmp_path, text), field)


@pytest.mark.parametrize(
    "start_time", ["0001-01-01T00:00:00+14:00", "9999-12-31T23:59:59-12:00", "1066-10-14T09:00:00+00:00"]
)
def test_start_time_at_the_ends_of_the_datetime_range(client, tmp_path, start_time):
    _assert_rejected(client, upload_csv(client, tmp_path, start_time=start_time), "start_time")


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"vehicle_id": "ICE\x001"}, "vehicle_id"),
        ({"extra": {"note": "a\x00b"}}, "extra.note"),
        ({"extra": {"k\x00ey": 1}}, "extra"),
    ],
)
def test_nul_characters_rejected_on_sqlite(client, tmp_path, changes, field):
    _assert_rejected(client, upload_csv(client, tmp_path, **changes), field)


def test_nul_characters_rejected_on_postgres(pg_cluster, make_client, tmp_path):
    """On PostgreSQL a NUL in a text or JSON value used to end in a database error (500)."""
    if isinstance(pg_cluster, str):
        pytest.skip(pg_cluster)
    client = make_client(database_url=pg_cluster.create_database())
    _assert_rejected(client, upload_csv(client, tmp_path, vehicle_id="ICE\x001"), "vehicle_id")
    _assert_rejected(client, upload_csv(client, tmp_path, extra={"note": "a\x00b"}), "extra.note")
    # the same value as a query filter: no match, not a database error
    r = client.get("/api/v1/runs", params={"vehicle_id": "ICE\x001"})
    assert r.status_code in (200, 422), r.text
    good = upload_csv(client, tmp_path)
    assert good.status_code == 201, good.text


def test_unexpected_errors_are_audited_too(client, tmp_path, monkeypatch):
    """A failure that is not the client's (a bug) still leaves its audit entry."""
    import app.runs.create as upload

    def boom(*args, **kwargs):
        raise RuntimeError("simulated bug")

    monkeypatch.setattr(upload, "ingest_upload", boom)  # the upload's parse (app.io.isolation)
    from fastapi.testclient import TestClient

    quiet = TestClient(client.app, headers=dict(client.headers), raise_server_exceptions=False)
    r = upload_file(quiet, csv_run(tmp_path), json.dumps(runfiles.metadata()), "text/csv")
    assert r.status_code == 500
    entry = last_upload_audit(client)
    assert entry["outcome"] == "error"
    assert entry["detail"]["status"] == 500
