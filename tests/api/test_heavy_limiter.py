"""Issue 24 defect 9: conversions of uploads run under a per-process limiter
(app.operations.heavy), so many uploads at once do not crowd the process's reads off the GIL;
through the API, concurrent uploads are converted one at a time and all succeed."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import anyio
import pytest

from app.io.isolation import ingest_upload as real_ingest
from app.operations.heavy import install_heavy_limiter, run_heavy
from tests.faults.support import hdf5_run, upload_file


class _App:
    class state:  # noqa: N801 - mimics app.state
        pass


def test_run_heavy_never_runs_more_than_the_limit_at_once():
    app = _App()
    install_heavy_limiter(app, 2)
    lock, active, peak = threading.Lock(), [0], [0]

    def work() -> int:
        with lock:
            active[0] += 1
            peak[0] = max(peak[0], active[0])
        time.sleep(0.05)
        with lock:
            active[0] -= 1
        return 7

    async def main() -> list[int]:
        results = []
        async with anyio.create_task_group() as tg:
            for _ in range(8):
                async def one() -> None:
                    results.append(await run_heavy(app, work))
                tg.start_soon(one)
        return results

    # an event loop of its own thread: a session fixture (the browser tests' Playwright) may hold
    # a running loop in this one
    with ThreadPoolExecutor(1) as pool:
        assert pool.submit(anyio.run, main).result() == [7] * 8 and peak[0] == 2
    with pytest.raises(ValueError):
        install_heavy_limiter(app, 0)


def test_concurrent_uploads_are_converted_one_at_a_time(make_client, tmp_path, monkeypatch):
    client = make_client(upload_ingest_concurrency=1)
    lock, active, peak = threading.Lock(), [0], [0]

    def counting_ingest(*args, **kwargs):
        with lock:
            active[0] += 1
            peak[0] = max(peak[0], active[0])
        try:
            time.sleep(0.1)
            return real_ingest(*args, **kwargs)
        finally:
            with lock:
                active[0] -= 1

    monkeypatch.setattr("app.runs.create.ingest_upload", counting_ingest)  # the parse child's launcher
    files = [hdf5_run(tmp_path, n=20_000) for _ in range(4)]
    with ThreadPoolExecutor(4) as pool:
        codes = [r.status_code for r in pool.map(lambda p: upload_file(client, p), files)]
    assert codes == [201] * 4 and peak[0] == 1
