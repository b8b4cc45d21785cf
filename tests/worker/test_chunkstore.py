"""Chunk results on a shared fsspec store (memory://) give the same profile as in the
run store directory; a failed chunk leaves no result; run files published to and fetched
from the shared store; helpers of the production mode."""

from __future__ import annotations

import os
import time

import numpy as np
import pandas as pd
import pytest

from app.analysis.settings import ProcessingSettings
from app.core.runstore import RunStore
from app.pipeline import assemble, plan_chunks, process_chunk, run_pipeline
from app.settings import Settings
from worker.chunkstore import ChunkStore
from worker.health import alive_file, check
from worker.hosting import libpq_url

SETTINGS = ProcessingSettings.from_dict({"chunk_seconds": 4.0})


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    from app.simulate.run import simulate_run

    path = tmp_path_factory.mktemp("tiny") / "tiny.h5"
    simulate_run(path, length_km=0.3, fs=5_000.0, seed=4, with_forces=False)
    return path


def test_memory_fsspec_store_matches_local_pipeline(tiny_run, tmp_path):
    import fsspec

    url = f"memory://trackvkf-test-{os.getpid()}-{time.monotonic_ns()}"
    runs = RunStore(tmp_path / "runs", url)
    store = ChunkStore(runs)
    assert not store.is_local
    chunks = plan_chunks(tiny_run, SETTINGS)
    assert len(chunks) >= 2
    for chunk in chunks:
        assert not store.exists(7, 3, chunk.index)
        store.write(7, 3, chunk.index, lambda out, c=chunk: process_chunk(tiny_run, SETTINGS, c, out))
        assert store.exists(7, 3, chunk.index)
        where = store.location(7, 3, chunk.index)
        assert where.startswith("memory://") and url.split("://")[1] in where
        assert where.endswith(f"/7/jobs/3/chunk-{chunk.index:05d}.npz")
    fs = fsspec.filesystem("memory")
    keys = fs.find(runs.shared.root)
    assert len(keys) == len(chunks) and not any(k.endswith(".tmp") for k in keys)
    # nothing in the run store directory
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").rglob("*.npz"))

    with store.local_copies(7, 3, [c.index for c in chunks]) as paths:
        remote = assemble(tiny_run, SETTINGS, paths)
    local = run_pipeline(tiny_run, SETTINGS, tmp_path / "local")
    assert len(remote.profiles) > 100
    pd.testing.assert_frame_equal(remote.profiles, local.profiles)

    # named job files (the assembled wheel results) go to the same place, atomically
    store.write_bytes(7, 3, "wheel-11.json", b'{"a": 1}')
    assert store.exists_named(7, 3, "wheel-11.json") and store.read_bytes(7, 3, "wheel-11.json") == b'{"a": 1}'
    with pytest.raises(ValueError, match="plain file name"):
        store.write_bytes(7, 3, "../escape.json", b"")

    runs.remove_run(7)  # the run's objects in the shared store go with it
    assert not any(store.exists(7, 3, c.index) for c in chunks)
    assert not store.exists_named(7, 3, "wheel-11.json")


def test_failed_chunk_leaves_no_result(tiny_run, tmp_path):
    url = f"memory://trackvkf-fail-{os.getpid()}-{time.monotonic_ns()}"
    store = ChunkStore(RunStore(tmp_path / "runs", url))
    chunk = plan_chunks(tiny_run, SETTINGS)[0]

    def broken(out):
        out.write_bytes(b"half a file")
        raise RuntimeError("worker died")

    with pytest.raises(RuntimeError, match="worker died"):
        store.write(1, 1, chunk.index, broken)
    assert not store.exists(1, 1, chunk.index)


def test_default_store_is_the_run_store_directory(tiny_run, tmp_path):
    runs = RunStore(tmp_path / "runs")
    store = ChunkStore(runs)
    chunk = plan_chunks(tiny_run, SETTINGS)[0]
    store.write(2, 5, chunk.index, lambda out: process_chunk(tiny_run, SETTINGS, chunk, out))
    assert runs.chunk_path(2, 5, chunk.index).is_file()
    assert store.location(2, 5, chunk.index) == f"2/jobs/5/chunk-{chunk.index:05d}.npz"
    with np.load(runs.chunk_path(2, 5, chunk.index)) as npz:
        assert int(npz["chunk_index"]) == chunk.index


def test_libpq_url_and_mode_selection():
    url = "postgresql+psycopg://u:p%40ss@db.example:5433/trackvkf"
    assert libpq_url(url) == "postgresql://u:p%40ss@db.example:5433/trackvkf"
    with pytest.raises(ValueError, match="database_url"):
        libpq_url("sqlite:///./var/trackvkf.db")
    assert Settings(database_url="sqlite:///x.db").is_sqlite
    assert not Settings(database_url=url).is_sqlite


def test_worker_health_file(tmp_path, monkeypatch):
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # no other worker's files
    path = alive_file(os.getpid())
    path.unlink(missing_ok=True)
    try:
        before = check(1.0)
        path.touch()
        assert check(1.0)
        old = time.time() - 10
        os.utime(path, (old, old))
        assert check(1.0) == before  # a stale file does not count
    finally:
        path.unlink(missing_ok=True)
    with pytest.raises(ValueError, match="max_age_s"):
        check(0)


def test_run_file_published_and_fetched_through_the_shared_store(tiny_run, tmp_path):
    import shutil

    url = f"memory://trackvkf-runs-{os.getpid()}-{time.monotonic_ns()}"
    api_host = RunStore(tmp_path / "api", url)
    run_file = api_host.run_file(5)
    run_file.parent.mkdir(parents=True)
    shutil.copyfile(tiny_run, run_file)
    api_host.publish_run_file(5)

    worker_host = RunStore(tmp_path / "worker", url)
    local = worker_host.local_file("5/run.h5")  # fetched once ...
    assert local == worker_host.run_file(5) and local.read_bytes() == tiny_run.read_bytes()
    assert worker_host.local_file("5/run.h5") == local  # ... then used from the host's own store
    assert not list(local.parent.glob("*.tmp"))
    with pytest.raises(FileNotFoundError, match="shared store"):
        worker_host.local_file("6/run.h5")
    with pytest.raises(FileNotFoundError, match="missing from the run store"):
        RunStore(tmp_path / "alone").local_file("5/run.h5")
    with pytest.raises(ValueError, match="leaves the run store"):
        worker_host.local_file("../5/run.h5")

    api_host.remove_run(5)
    assert not worker_host.shared.exists("5/run.h5") and not run_file.exists()
