"""Reads and small writes while large uploads stream in (issue 24 defect 9).

A real ``trackvkf serve --workers N`` (uvicorn, SQLite) holds a stored 20 km run (four wheels of
25 cm bins). Then, at once:

* ``--uploads`` (20) clients each stream a distinct 26 MB HDF5 run file (multipart, as a browser
  or ``curl -F`` sends it), throttled to ``--upload-mbps`` (2.5 MB/s each: 50 MB/s together, a
  LAN), so every upload is received, hashed, validated and written at the same time;
* ``wrk`` keeps ``--readers`` (50) connections busy with the stiffness map's profile queries
  (``max_points``, the map's columns, ``layout=columns``, gzip): half the whole-run view of a
  wheel, half a random zoom window (0.1–20 km), closed loop;
* a probe makes a small audited write (``PATCH /webhooks/{id}``: a description, recorded in the
  audit log) every 0.25 s and records how long each took.

Every latency is taken while the uploads stream (wrk runs from the first upload byte until the
last upload is answered, at least ``--min-seconds``; a 3 s wrk run warms the answer caches first). No worker runs (the jobs wait). Prints one Markdown row per run for
BENCHMARKS.md, with the machine's load average (the benchmark shares its cores)::

    python bench/bench_upload_load.py                     # 2 API processes, 20 × 26 MB, 50 readers
    python bench/bench_upload_load.py --uploads 0         # the same reads without uploads (reference)
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from bench_display_load import (  # noqa: E402
    _LUA,
    COLUMNS,
    MAX_POINTS,
    _cpu_times,
    _env,
    _free_port,
    _group_cpu_s,
    _serve,
    _stop,
)

_MIXED_LUA = _LUA.replace('if scenario == "zoom" then', 'if scenario == "zoom" and n %% 2 == 0 then')
FS = 10_000.0


def _upload_files(tmp: Path, n: int, mb: float) -> list[Path]:
    """``n`` distinct valid HDF5 run files of about ``mb`` MB (four float32 accelerations, speed,
    position)."""
    import h5py
    import numpy as np

    samples = int(mb * 1e6 / 32)
    files = []
    for seed in range(n):
        path = tmp / f"upload-{seed}.h5"
        rng = np.random.default_rng(seed)
        with h5py.File(path, "w") as h5:
            for name in ("Z11", "Z12", "Z41", "Z42"):
                h5.create_dataset(name, data=rng.normal(0.0, 1.0, samples).astype(np.float32))
            h5.create_dataset("speed", data=np.full(samples, 25.0))
            h5.create_dataset("position", data=np.arange(samples) * 25.0 / FS)
            h5.attrs["sample_rate_hz"] = FS
            h5.attrs["metadata"] = json.dumps({"vehicle_id": "BENCH", "line_id": "B", "track": "1", "direction": "up",
                                               "start_time": f"2026-03-{1 + seed % 28:02d}T08:00:00+00:00",
                                               "km_start": 0.0, "km_increasing": True})
        files.append(path)
    return files


async def _upload(client, path: Path, key: str, rate: float) -> tuple[float, int]:
    boundary = "bench" + os.urandom(8).hex()
    head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{path.name}\"\r\n"
            "Content-Type: application/x-hdf5\r\n\r\n").encode()
    tail = f"\r\n--{boundary}--\r\n".encode()
    size = path.stat().st_size
    piece = 256 * 1024

    async def body():
        yield head
        t0 = time.perf_counter()
        sent = 0
        with open(path, "rb") as fh:
            while block := fh.read(piece):
                yield block
                sent += len(block)
                wait = sent / rate - (time.perf_counter() - t0)
                if wait > 0:
                    await asyncio.sleep(wait)
        yield tail

    t = time.perf_counter()
    r = await client.post("/api/v1/runs", content=body(), headers={
        "Authorization": f"Bearer {key}", "Content-Type": f"multipart/form-data; boundary={boundary}",
        "Content-Length": str(len(head) + size + len(tail))})
    return time.perf_counter() - t, r.status_code


async def _probe(client, key: str, hook_id: int, stop: asyncio.Event, out: list[tuple[float, int]]) -> None:
    i = 0
    while not stop.is_set():
        t = time.perf_counter()
        r = await client.patch(f"/api/v1/webhooks/{hook_id}", json={"description": f"probe {i}"},
                               headers={"Authorization": f"Bearer {key}"})
        out.append((time.perf_counter() - t, r.status_code))
        i += 1
        await asyncio.sleep(max(0.0, 0.25 - (time.perf_counter() - t)))


async def _load(base_url: str, files: list[Path], admin_key: str, hook_id: int, rate: float,
                min_s: float) -> dict:
    import httpx

    limits = httpx.Limits(max_connections=len(files) + 4)
    async with httpx.AsyncClient(base_url=base_url, timeout=600.0, limits=limits) as client:
        stop = asyncio.Event()
        writes: list[tuple[float, int]] = []
        probe = asyncio.create_task(_probe(client, admin_key, hook_id, stop, writes))
        t0 = time.perf_counter()
        uploads = await asyncio.gather(*(_upload(client, p, admin_key, rate) for p in files))
        rest = min_s - (time.perf_counter() - t0)
        if rest > 0:
            await asyncio.sleep(rest)
        stop.set()
        await probe
    return {"uploads": uploads, "writes": writes, "seconds": time.perf_counter() - t0}


def _start_wrk(base_url: str, key: str, run_id: int, km: float, connections: int, tmp: Path) -> subprocess.Popen:
    """wrk with the map's queries until interrupted (SIGINT: it stops and prints its summary)."""
    lua = tmp / "mixed.lua"
    lua.write_text(_MIXED_LUA % {"scenario": "zoom", "key": key, "run_id": run_id, "km": km, "etags": "{}",
                                 "columns": COLUMNS, "max_points": MAX_POINTS})
    return subprocess.Popen(["wrk", "-t2", f"-c{connections}", "-d3600s", "--timeout", "30s", "-s", str(lua),
                             f"{base_url}/"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _stop_wrk(proc: subprocess.Popen) -> dict:
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    line = next((x for x in out.splitlines() if x.startswith("WRKJSON ")), None)
    if line is None:
        raise RuntimeError(f"wrk printed no summary: {out[-2000:]} {err[-2000:]}")
    return json.loads(line.removeprefix("WRKJSON "))


def _api_pids(server_pid: int) -> list[int]:
    """The serving processes (children of ``trackvkf serve``)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        if int(text[text.rindex(")") + 2:].split()[1]) == server_pid:
            out.append(int(stat.parent.name))
    return sorted(out)


def _pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, int(round(q * (len(s) - 1))))]


def _start_and_wait(base_url, key, run_id, km, connections, tmp, seconds) -> subprocess.Popen:
    proc = _start_wrk(base_url, key, run_id, km, connections, tmp)
    time.sleep(seconds)
    return proc


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2, help="API processes")
    parser.add_argument("--uploads", type=int, default=20)
    parser.add_argument("--upload-mb", type=float, default=26.0)
    parser.add_argument("--upload-mbps", type=float, default=2.5, help="MB/s per upload")
    parser.add_argument("--readers", type=int, default=50)
    parser.add_argument("--km", type=float, default=20.0)
    parser.add_argument("--min-seconds", type=float, default=12.0, help="shortest measuring window, s")
    parser.add_argument("--label", default="", help="first column of the table row")
    parser.add_argument("--keep", action="store_true")
    parser.add_argument("--profile", default=None, help="directory for py-spy profiles of the API processes")
    args = parser.parse_args(argv)
    if shutil.which("wrk") is None:
        print("wrk is not installed: apt-get install wrk", file=sys.stderr)
        return 2
    from display_run import store_display_run

    from app.db import auth_crud, migrate, webhooks
    from app.db.session import Database

    tmp = Path(tempfile.mkdtemp(prefix="bench-upload-load-"))
    server = None
    try:
        database_url = f"sqlite:///{tmp / 'db.sqlite'}"
        migrate.upgrade(database_url)
        run_id, viewer_key, _ = store_display_run(database_url, args.km)
        db = Database(database_url)
        with db.write() as s:
            _, admin_key = auth_crud.create_api_key(s, "bench-admin", "admin", created_by="bench")
            hook_id = webhooks.create_webhook(s, "https://hooks.example.org/bench").id
        db.dispose()
        files = _upload_files(tmp, args.uploads, args.upload_mb)
        port = _free_port()
        base_url = f"http://127.0.0.1:{port}"
        server = _serve(_env(database_url, tmp / "runs"), port, args.workers, tmp / "server.log")
        # warm-up: every process has answered the map queries once
        _stop_wrk(_start_and_wait(base_url, viewer_key, run_id, args.km, args.readers, tmp, 3.0))
        profilers = []
        if args.profile:
            for pid in _api_pids(server.pid):
                profilers.append(subprocess.Popen(
                    [str(Path(sys.executable).with_name("py-spy")), "record", "--pid", str(pid), "--rate", "50",
                     "--format", "raw", "--threads", "--gil", "-o", str(Path(args.profile) / f"api-{pid}.txt")],
                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        load0 = os.getloadavg()[0]
        busy0, steal0 = _cpu_times()
        api0 = _group_cpu_s(server.pid)
        reader = _start_wrk(base_url, viewer_key, run_id, args.km, args.readers, tmp)
        result = asyncio.run(_load(base_url, files, admin_key, hook_id, args.upload_mbps * 1e6, args.min_seconds))
        reads = _stop_wrk(reader)
        for p in profilers:
            p.send_signal(signal.SIGINT)
            p.wait(timeout=60)
        busy1, steal1 = _cpu_times()
        api1 = _group_cpu_s(server.pid)
        load1 = os.getloadavg()[0]
        n_reads = reads["requests"]
        errors = sum(reads["errors"].values())
        bad = sum(n for code, n in reads["statuses"].items() if code != "200")
        writes = [w for w, _ in result["writes"]]
        up_s = [u for u, _ in result["uploads"]]
        up_codes = sorted({c for _, c in result["uploads"]})
        wall = result["seconds"]
        print(f"\n{args.label or 'run'}: {args.workers} API processes, {args.uploads} × {args.upload_mb:g} MB "
              f"uploads at {args.upload_mbps:g} MB/s each, {args.readers} readers, window {wall:.1f} s")
        print("| build | reads | reads/s | read p50 s | read p99 s | read max s | read errors | write p50 s | "
              "write p99 s | write max s | writes | upload s (min–max) | upload status | API CPU s | machine busy % "
              "| stolen CPU s | load avg before → after |")
        print(f"| {args.label} | {n_reads} | {n_reads / max(wall, 1e-9):.0f} | {reads['p50_ms'] / 1000:.2f} | "
              f"{reads['p99_ms'] / 1000:.2f} | {reads['max_ms'] / 1000:.2f} | {errors + bad} | "
              f"{_pct(writes, 0.5):.2f} | {_pct(writes, 0.99):.2f} | {max(writes, default=float('nan')):.2f} | "
              f"{len(writes)} | {min(up_s, default=0):.1f}–{max(up_s, default=0):.1f} | {up_codes} | "
              f"{api1 - api0:.0f} | {100 * (busy1 - busy0) / (wall * (os.cpu_count() or 1)):.0f} | "
              f"{steal1 - steal0:.0f} | {load0:.1f} → {load1:.1f} |")
        return 0
    finally:
        if server is not None:
            _stop(server)
        if not args.keep:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
