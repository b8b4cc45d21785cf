"""Uploads: streamed creation, duplicates, and every bad input leaving nothing behind."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from sqlalchemy import func, select

from app.db.models import Job, Run
from app.db.session import Database
from tests.api import runfiles
from tests.api.support import store_files


def _counts(settings) -> tuple[int, int]:
    db = Database(settings.database_url)
    try:
        with db.read() as s:
            return (
                s.scalar(select(func.count()).select_from(Run)),
                s.scalar(select(func.count()).select_from(Job)),
            )
    finally:
        db.dispose()


def _assert_nothing_left(client) -> None:
    assert _counts(client.settings) == (0, 0)
    assert store_files(client.settings.run_store) == []


def _post_file(client, path, *, metadata=None, fmt=None, filename=None, content_type=None):
    data = {}
    if metadata is not None:
        data["metadata"] = json.dumps(metadata)
    if fmt is not None:
        data["format"] = fmt
    with open(path, "rb") as fh:
        return client.post(
            "/api/v1/runs",
            files={"file": (filename or path.name, fh, content_type or "application/octet-stream")},
            data=data,
        )


def test_upload_hdf5_creates_run_file_and_queued_job(client, tmp_path):
    path = runfiles.write_hdf5(tmp_path / "good.h5")
    sha = hashlib.sha256(path.read_bytes()).hexdigest()
    r = _post_file(client, path)
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["sha256"] == sha
    assert body["size_bytes"] == path.stat().st_size
    assert body["source_format"] == "hdf5"
    assert body["line_id"] == "4010" and body["vehicle_id"] == "ICE-1"
    assert body["summary"]["fs"] == runfiles.FS
    assert body["summary"]["n_samples"] == runfiles.N
    assert body["latest_job"]["status"] == "queued"
    assert body["latest_job"]["settings"]["n_wheel_orders"] == 11
    assert r.headers["location"] == f"/api/v1/runs/{body['id']}"
    files = store_files(client.settings.run_store)
    assert [p.relative_to(client.settings.run_store).as_posix() for p in files] == [
        f"{body['id']}/run.h5"
    ]
    assert _counts(client.settings) == (1, 1)


def test_duplicate_upload_returns_existing_run(client, tmp_path):
    path = runfiles.write_hdf5(tmp_path / "good.h5")
    first = _post_file(client, path)
    assert first.status_code == 201
    second = _post_file(client, path, filename="renamed.h5")
    assert second.status_code == 200
    assert second.json()["id"] == first.json()["id"]
    assert _counts(client.settings) == (1, 1)
    assert len(store_files(client.settings.run_store)) == 1


def test_raw_body_csv_upload_with_query_metadata(client, tmp_path):
    path = runfiles.write_csv(tmp_path / "run.csv")
    r = client.post(
        "/api/v1/runs",
        params={"format": "csv", "metadata": json.dumps(runfiles.metadata()), "filename": "a/../run.csv"},
        content=path.read_bytes(),
        headers={"content-type": "text/csv"},
    )
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["source_format"] == "csv"
    assert body["original_filename"] == "run.csv"
    assert body["metadata"]["direction"] == "up"


def test_parquet_upload_with_form_metadata(client, tmp_path):
    import pandas as pd

    path = tmp_path / "run.parquet"
    pd.DataFrame(runfiles.channels()).to_parquet(path)
    r = _post_file(client, path, metadata=runfiles.metadata())
    assert r.status_code == 201, r.text
    assert r.json()["source_format"] == "parquet"


def _bad_hdf5(kind: str, tmp_path):
    data = runfiles.channels()
    md = runfiles.metadata(sample_rate_hz=None)
    fs = runfiles.FS
    if kind == "missing_channel":
        for c in runfiles.ACCEL:
            data.pop(c)
    elif kind == "unequal_lengths":
        data["Z12"] = data["Z12"][:-100]
    elif kind == "non_monotonic_position":
        pos = data["position"].copy()
        pos[5000:] -= 10.0
        data["position"] = pos
        data.pop("speed")
    elif kind == "too_many_nan":
        z = data["Z11"].copy()
        z[::10] = np.nan
        data["Z11"] = z
    elif kind == "sample_rate_missing":
        fs = None
    else:
        raise AssertionError(kind)
    return runfiles.write_hdf5(tmp_path / f"{kind}.h5", data, md, fs=fs)


@pytest.mark.parametrize(
    ("kind", "field", "words"),
    [
        ("missing_channel", "Z11", "missing channel"),
        ("unequal_lengths", "Z12", "unequal length"),
        ("non_monotonic_position", "position", "non-monotonic"),
        ("too_many_nan", "Z11", "nan"),
        ("sample_rate_missing", "sample_rate_hz", "sample rate missing"),
    ],
)
def test_bad_file_is_rejected_and_leaves_nothing(client, tmp_path, kind, field, words):
    r = _post_file(client, _bad_hdf5(kind, tmp_path))
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["field"] == field
    assert body["detail"].startswith(f"{field}: ")
    assert words in body["detail"].lower()
    _assert_nothing_left(client)


def test_unknown_format_bytes(client, tmp_path):
    path = tmp_path / "run.bin"
    path.write_bytes(b"\x00\x01garbage" * 1000)
    r = _post_file(client, path)
    assert r.status_code == 422
    assert r.json()["field"] == "format"
    assert "unknown format" in r.json()["detail"]
    _assert_nothing_left(client)


def test_unknown_declared_format(client, tmp_path):
    path = runfiles.write_hdf5(tmp_path / "good.h5")
    r = _post_file(client, path, fmt="xlsx")
    assert r.status_code == 422
    assert r.json()["detail"].startswith("format: unknown format 'xlsx'")
    _assert_nothing_left(client)


def test_declared_format_mismatch(client, tmp_path):
    path = runfiles.write_hdf5(tmp_path / "good.h5")
    r = _post_file(client, path, fmt="parquet")
    assert r.status_code == 422
    assert r.json()["field"] == "format"
    _assert_nothing_left(client)


def test_csv_without_metadata_names_missing_field(client, tmp_path):
    path = runfiles.write_csv(tmp_path / "run.csv")
    r = _post_file(client, path)
    assert r.status_code == 422
    assert r.json()["field"] in {"metadata", "vehicle_id", "sample_rate_hz", "start_time"}
    _assert_nothing_left(client)


def test_invalid_metadata_json(client, tmp_path):
    path = runfiles.write_csv(tmp_path / "run.csv")
    with open(path, "rb") as fh:
        r = client.post(
            "/api/v1/runs", files={"file": ("run.csv", fh, "text/csv")}, data={"metadata": "{oops"}
        )
    assert r.status_code == 422
    assert r.json()["detail"].startswith("metadata: not valid JSON")
    _assert_nothing_left(client)


def test_bad_metadata_value_names_field(client, tmp_path):
    path = runfiles.write_csv(tmp_path / "run.csv")
    r = _post_file(client, path, metadata=runfiles.metadata(start_time="2026-03-02T08:00:00"))
    assert r.status_code == 422
    assert r.json()["field"] == "start_time"
    _assert_nothing_left(client)


def test_file_over_cap_gets_413(make_client, tmp_path):
    client = make_client(max_upload_bytes=64 * 1024)
    path = runfiles.write_csv(tmp_path / "run.csv")
    assert path.stat().st_size > 64 * 1024
    r = _post_file(client, path, metadata=runfiles.metadata())
    assert r.status_code == 413
    assert r.json()["field"] == "file"
    assert "size limit of 65536 bytes" in r.json()["detail"]
    _assert_nothing_left(client)


def test_raw_body_over_cap_without_content_length(make_client, tmp_path):
    client = make_client(max_upload_bytes=64 * 1024)

    def body():
        for _ in range(40):
            yield b"x" * 4096

    r = client.post("/api/v1/runs", params={"format": "csv"}, content=body())
    assert r.status_code == 413
    _assert_nothing_left(client)


def test_empty_and_malformed_bodies(client):
    r = client.post("/api/v1/runs", content=b"")
    assert r.status_code == 422 and r.json()["field"] == "file"
    r = client.post(
        "/api/v1/runs",
        content=b"--xyz\r\nContent-Disposition: form-data; name=\"file\"; filename=\"a.h5\"\r\n\r\nabc",
        headers={"content-type": "multipart/form-data; boundary=xyz"},
    )
    assert r.status_code in (400, 422)
    r = client.post(
        "/api/v1/runs",
        files={"other": ("a.h5", b"abc", "application/octet-stream")},
    )
    assert r.status_code == 422 and r.json()["field"] == "form"
    _assert_nothing_left(client)


def test_openapi_documents_upload_bodies(client):
    spec = client.get("/openapi.json").json()
    body = spec["paths"]["/api/v1/runs"]["post"]["requestBody"]["content"]
    assert "multipart/form-data" in body and "application/octet-stream" in body


def test_concurrent_duplicate_commit_leaves_no_directory(client, tmp_path):
    """Two uploads of the same file racing: the loser's insert fails on the unique
    sha256 and its upload directory is not installed as a run directory."""
    from sqlalchemy.exc import IntegrityError

    from app.core.runstore import RunStore
    from app.core.security import Actor, Principal
    from app.io import ingest
    from app.runs.create import UploadedFile, insert_run

    path = runfiles.write_hdf5(tmp_path / "good.h5")
    first = _post_file(client, path).json()
    store = RunStore(client.settings.run_store)
    upload_dir = store.new_upload_dir()
    summary = ingest(path, None, None, upload_dir / "run.h5")
    received = UploadedFile(path=path, sha256=first["sha256"], size=path.stat().st_size)
    db = Database(client.settings.database_url)
    try:
        with pytest.raises(IntegrityError):
            insert_run(db, store, upload_dir, summary, received, "hdf5", Actor(Principal("test", "admin")))
    finally:
        db.dispose()
    assert store.run_ids_on_disk() == [first["id"]]
    assert _counts(client.settings) == (1, 1)
