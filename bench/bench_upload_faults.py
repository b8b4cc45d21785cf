"""Hostile and faulty uploads against the real API process (issue 18): memory and disk full.

Memory: peak RSS growth of the uvicorn API process (``VmHWM``, reset before each
upload through ``/proc/<pid>/clear_refs``) while it receives and rejects or
accepts one streamed upload:

* a CSV whose single data line is 200 MB / 400 MB long (the issue: 1.67 GB / 3.0 GB),
* a normal 250 MB CSV (3 M rows x 10 channels),
* a 435 MB Parquet file with one row group (6 M rows x 10 channels, uncompressed).

Disk full (needs root to mount a tmpfs; skipped otherwise): run store on a
20 MiB tmpfs, ``TRACKVKF_MIN_FREE_BYTES=0``, an 11.6 MB HDF5 run uploaded three
times (the issue: 500, then a segfault of the API), then a run that fits.

Usage: ``.venv/bin/python bench/bench_upload_faults.py [--skip-memory] [--skip-disk]``
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.api import runfiles  # noqa: E402
from tests.e2e.conftest import running_service  # noqa: E402
from tests.faults.support import (  # noqa: E402
    TmpfsUnavailable,
    hdf5_run,
    mounted_tmpfs,
    single_line_csv,
    upload_file,
    upload_peak_growth_mb,
)


def _normal_csv(path: Path, rows: int) -> Path:
    import numpy as np

    rng = np.random.default_rng(0)
    cols = ["Z11", "Z12", "Z41", "Z42", "Q11", "Q12", "Q41", "Q42", "speed", "position"]
    with open(path, "w") as fh:
        fh.write(",".join(cols) + "\n")
        for a in range(0, rows, 1 << 18):
            n = min(1 << 18, rows - a)
            d = rng.normal(size=(n, len(cols)))
            d[:, 8] = 20.0
            d[:, 9] = (a + np.arange(n)) * 20.0 / runfiles.FS
            np.savetxt(fh, d, delimiter=",", fmt="%.6g")
    return path


def _parquet_one_row_group(path: Path, rows: int) -> Path:
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    rng = np.random.default_rng(1)
    cols = {c: rng.normal(size=rows) for c in ("Z11", "Z12", "Z41", "Z42", "Q11", "Q12", "Q41", "Q42")}
    cols["speed"] = np.full(rows, 20.0)
    cols["position"] = np.arange(rows) * 20.0 / runfiles.FS
    pq.write_table(pa.table(cols), path, row_group_size=rows, compression="NONE")
    return path


def memory(work: Path) -> None:
    cases = [
        ("single-line CSV, 200 MB", lambda: single_line_csv(work / "line200.csv", 200), "text/csv"),
        ("single-line CSV, 400 MB", lambda: single_line_csv(work / "line400.csv", 400), "text/csv"),
        ("CSV 3 M rows x 10 channels", lambda: _normal_csv(work / "normal.csv", 3_000_000), "text/csv"),
        ("Parquet, one row group of 6 M rows", lambda: _parquet_one_row_group(work / "one.parquet", 6_000_000),
         "application/vnd.apache.parquet"),
    ]
    print("| upload | size MB | status | API peak RSS growth MB | s |")
    print("|---|---|---|---|---|")
    with running_service(work / "svc", env_overrides={"TRACKVKF_MAX_UPLOAD_BYTES": str(1 << 31)}) as svc:
        r, _ = upload_peak_growth_mb(svc, runfiles.write_csv(work / "warm.csv"), runfiles.metadata())
        assert r.status_code == 201, r.text
        for name, make, ctype in cases:
            path = make()
            t0 = time.perf_counter()
            r, growth = upload_peak_growth_mb(svc, path, runfiles.metadata(), ctype)
            took = time.perf_counter() - t0
            size = path.stat().st_size / 1e6
            print(f"| {name} | {size:.0f} | {r.status_code} | {growth:.0f} | {took:.1f} |", flush=True)
            if r.status_code >= 400:
                print(f"|   ({r.json()['detail'][:120]}) | | | | |")
            path.unlink()


def disk_full(work: Path) -> None:
    try:
        with mounted_tmpfs(work / "store", 20 << 20) as store:
            with running_service(work / "svc-disk", run_store=store,
                                 env_overrides={"TRACKVKF_MIN_FREE_BYTES": "0"}) as svc:
                with svc.client(timeout=120) as client:
                    for i in range(3):
                        path = hdf5_run(work, n=362_000)
                        r = upload_file(client, path)
                        alive = svc.api.poll() is None
                        left = [p.name for p in store.rglob("*") if p.is_file()]
                        print(f"upload {i + 1} ({path.stat().st_size / 1e6:.1f} MB): {r.status_code} "
                              f"{r.json().get('detail', '')[:110]!r}; API alive: {alive}; files left: {left}")
                    health = client.get("/api/v1/health").json()
                    print(f"health: {health['status']}, run_store {health['run_store']}, "
                          f"free {health['run_store_free_bytes'] / 1e6:.1f} MB")
                    r = upload_file(client, hdf5_run(work, n=40_000))
                    print(f"a 1.3 MB run afterwards: {r.status_code}; API alive: {svc.api.poll() is None}")
    except TmpfsUnavailable as exc:
        print(f"disk-full case skipped: {exc}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-memory", action="store_true")
    parser.add_argument("--skip-disk", action="store_true")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="trackvkf-bench-faults-"))
    try:
        if not args.skip_memory:
            memory(work)
        if not args.skip_disk:
            disk_full(work)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
