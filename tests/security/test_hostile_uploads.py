"""Crafted files uploaded over the API: each is rejected with a 4xx naming the problem
and leaves no trace (no run row, no job, no file in the run store); the rejection
is in the audit log."""

from __future__ import annotations

import json
import zlib
from pathlib import Path

import h5py
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from sqlalchemy import func, select

from app.db.models import AuditEntry, Job, Run
from app.db.session import Database
from tests.api import runfiles
from tests.api.support import store_files

BOMB_SAMPLES = 40_000_000  # 160 MB of float32 zeros per channel, a few hundred kB compressed


def _post(client, path: Path, *, metadata=None, content_type="application/octet-stream", filename=None):
    data = {"metadata": json.dumps(metadata)} if metadata is not None else {}
    with open(path, "rb") as fh:
        return client.post(
            "/api/v1/runs", files={"file": (filename or path.name, fh, content_type)}, data=data
        )


def _assert_rejected_without_trace(client, response, status: int, field: str, words: str) -> None:
    assert response.status_code == status, response.text
    body = response.json()
    assert body["field"] == field, body
    assert words in body["detail"], body
    db = Database(client.settings.database_url)
    try:
        with db.read() as s:
            assert s.scalar(select(func.count()).select_from(Run)) == 0
            assert s.scalar(select(func.count()).select_from(Job)) == 0
            audit = s.scalars(select(AuditEntry).where(AuditEntry.action == "run.upload")).all()
    finally:
        db.dispose()
    assert store_files(client.settings.run_store) == []
    assert [a.outcome for a in audit] == ["rejected"]
    assert audit[0].detail["status"] == status


def _base_h5(path: Path) -> h5py.File:
    data = runfiles.channels(n=10_000)
    h5 = h5py.File(path, "w")
    for name in ("Z11", "speed"):
        h5.create_dataset(name, data=data[name])
    h5.attrs["sample_rate_hz"] = runfiles.FS
    h5.attrs["metadata"] = json.dumps(runfiles.metadata(sample_rate_hz=None))
    return h5


def test_hdf5_external_link_to_etc_passwd(client, tmp_path):
    path = tmp_path / "link.h5"
    with _base_h5(path) as h5:
        h5["Z12"] = h5py.ExternalLink("/etc/passwd", "/")
    r = _post(client, path)
    _assert_rejected_without_trace(client, r, 422, "Z12", "external link to /etc/passwd")


def test_hdf5_virtual_dataset(client, tmp_path):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as h5:
        h5["data"] = np.zeros(4000, dtype="f4")
    layout = h5py.VirtualLayout(shape=(4000,), dtype="f4")
    layout[:] = h5py.VirtualSource(str(other), "data", shape=(4000,))
    path = tmp_path / "vds.h5"
    with _base_h5(path) as h5:
        h5.create_virtual_dataset("Z12", layout)
    r = _post(client, path)
    _assert_rejected_without_trace(client, r, 422, "Z12", "virtual datasets are not allowed")


def test_hdf5_external_storage(client, tmp_path):
    path = tmp_path / "ext.h5"
    with _base_h5(path) as h5:
        h5.create_dataset("Z12", shape=(4000,), dtype="<f4", external=[("/etc/passwd", 0, 16000)])
    r = _post(client, path)
    _assert_rejected_without_trace(client, r, 422, "Z12", "external storage")


def test_hdf5_gzip_bomb(client, tmp_path):
    """Two channels of 40 M zeros, gzip-compressed: a few hundred kB decoding to 480 MB."""
    path = tmp_path / "bomb.h5"
    chunk = 1_000_000
    with h5py.File(path, "w") as h5:
        for name, dtype in (("Z11", "f4"), ("speed", "f8")):
            ds = h5.create_dataset(
                name, shape=(BOMB_SAMPLES,), dtype=dtype, chunks=(chunk,), compression="gzip"
            )
            packed = zlib.compress(np.zeros(chunk, dtype=dtype).tobytes(), 9)
            for a in range(0, BOMB_SAMPLES, chunk):  # the same deflated chunk, written raw
                ds.id.write_direct_chunk((a,), packed)
        h5.attrs["sample_rate_hz"] = runfiles.FS
        h5.attrs["metadata"] = json.dumps(runfiles.metadata(sample_rate_hz=None))
    assert path.stat().st_size < 5_000_000
    r = _post(client, path)
    _assert_rejected_without_trace(client, r, 422, "file", "compression bomb")


def test_hdf5_unallocated_storage_bomb(client, tmp_path):
    """A dataset declared 40 M samples long with no storage written (reads as fill value)."""
    path = tmp_path / "sparse.h5"
    with h5py.File(path, "w") as h5:
        h5.create_dataset("Z11", shape=(BOMB_SAMPLES,), dtype="f8", chunks=(65536,))
        h5.create_dataset("speed", shape=(BOMB_SAMPLES,), dtype="f8", chunks=(65536,))
        h5.attrs["sample_rate_hz"] = runfiles.FS
        h5.attrs["metadata"] = json.dumps(runfiles.metadata(sample_rate_hz=None))
    r = _post(client, path)
    _assert_rejected_without_trace(client, r, 422, "file", "unallocated storage")


def test_hdf5_plugin_filter(client, tmp_path):
    """A dataset whose filter (here id 307, bzip2) would load a plugin library."""
    path = tmp_path / "plugin.h5"
    with _base_h5(path) as h5:
        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_chunk((1000,))
        dcpl.set_filter(307, h5py.h5z.FLAG_OPTIONAL)
        space = h5py.h5s.create_simple((4000,))
        h5py.h5d.create(h5.id, b"Z12", h5py.h5t.IEEE_F32LE, space, dcpl=dcpl).close()
    r = _post(client, path)
    _assert_rejected_without_trace(client, r, 422, "Z12", "HDF5 filter 307 is not allowed")


def test_gzip_csv_bomb(client, tmp_path):
    """A gzip CSV of 200 MB of '0,0' lines compressed about 1000-fold."""
    path = tmp_path / "bomb.csv.gz"
    line_block = b"0,0\n" * 250_000  # 1 MB
    compressor = zlib.compressobj(9, zlib.DEFLATED, 31)  # gzip container
    with open(path, "wb") as fh:
        fh.write(compressor.compress(b"Z11,speed\n"))
        for _ in range(200):
            fh.write(compressor.compress(line_block))
        fh.write(compressor.flush())
    assert path.stat().st_size < 1_000_000
    r = _post(client, path, metadata=runfiles.metadata(), content_type="application/gzip")
    _assert_rejected_without_trace(client, r, 422, "file", "decompression bomb")


def test_csv_with_a_million_columns(client, tmp_path):
    path = tmp_path / "wide.csv"
    header = ",".join(f"c{i}" for i in range(1_000_000))
    path.write_text(header + "\n" + ",".join("0" for _ in range(1_000_000)) + "\n")
    r = _post(client, path, metadata=runfiles.metadata(), content_type="text/csv")
    _assert_rejected_without_trace(client, r, 422, "file", "header row is longer than")


def test_csv_with_too_many_short_columns(client, tmp_path):
    path = tmp_path / "wide.csv"
    path.write_text(",".join("Z11" for _ in range(1000)) + "\n")
    r = _post(client, path, metadata=runfiles.metadata(), content_type="text/csv")
    _assert_rejected_without_trace(client, r, 422, "file", "1000 columns exceed the limit")


@pytest.mark.parametrize("keep", [0.5, 0.99])
def test_truncated_parquet(client, tmp_path, keep):
    whole = tmp_path / "whole.parquet"
    pq.write_table(pa.table(runfiles.channels(n=20_000)), whole)
    data = whole.read_bytes()
    path = tmp_path / "cut.parquet"
    path.write_bytes(data[: int(len(data) * keep)])
    r = _post(client, path, metadata=runfiles.metadata())
    _assert_rejected_without_trace(client, r, 422, "format", "PAR1")


def test_unsupported_content_type(client, tmp_path):
    path = runfiles.write_hdf5(tmp_path / "good.h5")
    r = _post(client, path, content_type="text/html")
    _assert_rejected_without_trace(client, r, 415, "content_type", "unsupported content type")
    r = client.post("/api/v1/runs", content=path.read_bytes(), headers={"Content-Type": "image/png"})
    assert r.status_code == 415


def test_content_type_disagreeing_with_magic_bytes(client, tmp_path):
    path = runfiles.write_csv(tmp_path / "run.csv")
    r = client.post(
        "/api/v1/runs",
        content=path.read_bytes(),
        headers={"Content-Type": "application/x-hdf5"},
        params={"metadata": json.dumps(runfiles.metadata())},
    )
    _assert_rejected_without_trace(client, r, 422, "format", "no HDF5 signature")


def test_client_file_name_never_becomes_a_path(client, tmp_path):
    path = runfiles.write_hdf5(tmp_path / "good.h5")
    r = _post(client, path, filename="../../../../tmp/evil.h5")
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["original_filename"] == "evil.h5"
    files = [p.relative_to(client.settings.run_store).as_posix() for p in store_files(client.settings.run_store)]
    assert files == [f"{body['id']}/run.h5"]
