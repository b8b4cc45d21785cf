"""Many engineers on the stiffness map at once: display queries of a 100 km run under load.

A real ``trackvkf serve --workers N`` (uvicorn) serves a synthetic 100 km run (400 000 bins per
wheel, four wheels); ``wrk`` (Debian package ``wrk``; C, two threads) keeps 50 connections busy
with the dashboard's display query, as the page asks it (``max_points``, the map's columns,
``layout=columns``, ``Accept-Encoding: gzip``). While it runs, a separate probe process logs in
every second and uploads a small run every third second, and records how long each write took.

Scenarios:

``map``
    every request asks the whole-run view of one of the four wheels (what every engineer's
    browser asks when the map opens; answered from the per-process answer cache after the first);
``zoom``
    every request a random km window (0.1–20 km, log-uniform) of a random wheel: nearly every
    answer is computed afresh (sliced from the wheel's arrays in memory, or read from the database
    until they are read, decimated, encoded);
``revalidate``
    the ``map`` requests sent with the ETag the browser holds (``If-None-Match``: 304).

    python bench/bench_display_load.py                         # SQLite, all scenarios, 30 s each
    python bench/bench_display_load.py --database postgresql   # throw-away PostgreSQL cluster
    python bench/bench_display_load.py --workers 1 --scenario zoom --duration 20

Prints a Markdown table for BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

COLUMNS = "sleeper_amp,speed_mean,sleeper_force_amp"
MAX_POINTS = 2400  # what a 1200 px wide map asks (two points per pixel, in steps of 200)
USER, PASSWORD = "bench-user", "bench password 1"

_LUA = r"""
local scenario, key, run_id, km = "%(scenario)s", "%(key)s", %(run_id)d, %(km)f
local wheels = {"11", "12", "41", "42"}
local etags = %(etags)s
local base = "/api/v1/runs/" .. run_id .. "/profile?columns=%(columns)s&layout=columns&max_points=%(max_points)d"
local n = 0
local threads = {}

function setup(thread)
  thread:set("id", #threads + 1)
  table.insert(threads, thread)
end

function init(args)
  math.randomseed(os.time() * 1000 + id)
  counts = {}
  wrk.headers["Authorization"] = "Bearer " .. key
  wrk.headers["Accept-Encoding"] = "gzip"
end

function request()
  n = n + 1
  local wheel = wheels[(n %% 4) + 1]
  local path = base .. "&wheel=" .. wheel
  local headers = nil
  if scenario == "zoom" then
    wheel = wheels[math.random(4)]
    local len = 0.1 * (200 ^ math.random())
    local a = math.random() * (km - len)
    path = base .. "&wheel=" .. wheel .. string.format("&km_from=%%.4f&km_to=%%.4f", a, a + len)
  elseif scenario == "revalidate" then
    headers = {["If-None-Match"] = etags[wheel], ["Authorization"] = "Bearer " .. key, ["Accept-Encoding"] = "gzip"}
  end
  return wrk.format("GET", path, headers)
end

function response(status, headers, body)
  counts[status] = (counts[status] or 0) + 1
end

function done(summary, latency, requests)
  local statuses = {}
  for _, t in ipairs(threads) do
    local c = t:get("counts")
    for s, k in pairs(c) do statuses[tostring(s)] = (statuses[tostring(s)] or 0) + k end
  end
  local parts = {}
  for s, k in pairs(statuses) do table.insert(parts, string.format('"%%s": %%d', s, k)) end
  io.write(string.format(
    'WRKJSON {"requests": %%d, "duration_us": %%d, "bytes": %%d, "errors": {"connect": %%d, "read": %%d, "write": %%d, "status": %%d, "timeout": %%d}, "p50_ms": %%.1f, "p90_ms": %%.1f, "p99_ms": %%.1f, "max_ms": %%.1f, "statuses": {%%s}}\n',
    summary.requests, summary.duration, summary.bytes, summary.errors.connect, summary.errors.read,
    summary.errors.write, summary.errors.status, summary.errors.timeout,
    latency:percentile(50) / 1000, latency:percentile(90) / 1000, latency:percentile(99) / 1000,
    latency.max / 1000, table.concat(parts, ", ")))
end
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cpu_times() -> tuple[float, float]:
    """(busy, steal) CPU seconds of the whole machine so far (/proc/stat)."""
    fields = [float(x) for x in Path("/proc/stat").read_text().split("\n")[0].split()[1:]]
    tick = os.sysconf("SC_CLK_TCK")
    user, nice, system, idle, iowait, irq, softirq, steal = fields[:8]
    return (user + nice + system + irq + softirq) / tick, steal / tick


def _group_cpu_s(pgid: int) -> float:
    """CPU seconds (user + system) used so far by the live processes of process group ``pgid``."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0.0
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        fields = text[text.rindex(")") + 2:].split()
        if int(fields[2]) == pgid:  # field 5 of stat: process group
            total += (int(fields[11]) + int(fields[12])) / tick  # fields 14, 15: utime, stime
    return total


def _group_rss_mb(pgid: int) -> float:
    """Resident memory (MB) of the live processes of process group ``pgid`` (the API processes)."""
    total = 0
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
            if int(text[text.rindex(")") + 2:].split()[2]) != pgid:
                continue
            status = (stat.parent / "status").read_text()
        except (OSError, ValueError):
            continue
        total += next((int(x.split()[1]) for x in status.splitlines() if x.startswith("VmRSS:")), 0)
    return total / 1024


def _probe(base_url: str, key: str, files: list[str], out: str, stop_file: str) -> None:
    """Writes during the load: a login every second, an upload every third; their durations."""
    import httpx

    results: list[dict] = []
    with httpx.Client(base_url=base_url, timeout=60.0) as client:
        i = 0
        while not Path(stop_file).exists():
            t = time.perf_counter()
            r = client.post("/api/v1/auth/login", json={"username": USER, "password": PASSWORD})
            results.append({"kind": "login", "s": time.perf_counter() - t, "status": r.status_code})
            if i % 3 == 0 and i // 3 < len(files):
                path = files[i // 3]
                t = time.perf_counter()
                with open(path, "rb") as fh:
                    r = client.post("/api/v1/runs", headers={"Authorization": f"Bearer {key}"},
                                    files={"file": (Path(path).name, fh, "application/x-hdf5")})
                results.append({"kind": "upload", "s": time.perf_counter() - t, "status": r.status_code})
            i += 1
            time.sleep(max(0.0, 1.0 - (time.perf_counter() - t)))
    Path(out).write_text(json.dumps(results))


def _env(database_url: str, store: Path) -> dict[str, str]:
    return {
        **os.environ,
        "TRACKVKF_DATABASE_URL": database_url,
        "TRACKVKF_RUN_STORE": str(store),
        "TRACKVKF_LOG_LEVEL": "WARNING",
        "TRACKVKF_LOGIN_RATE_LIMIT": "100000",
        "TRACKVKF_LOGIN_ADDRESS_RATE_LIMIT": "100000",
        "TRACKVKF_UPLOAD_RATE_LIMIT": "100000",
        "PYTHONUNBUFFERED": "1",
    }


def _prepare(database_url: str, km: float, tmp: Path, n_uploads: int) -> tuple[int, str, str, list[str]]:
    """Migrate, store the run, a user and an engineer key, simulate the probe's upload files."""
    from display_run import store_display_run

    from app.db import auth_crud, migrate
    from app.db.session import Database
    from app.simulate.run import simulate_run

    migrate.upgrade(database_url)
    t = time.perf_counter()
    run_id, viewer_key, n_rows = store_display_run(database_url, km)
    print(f"stored {n_rows} profile rows in {time.perf_counter() - t:.1f} s", flush=True)
    db = Database(database_url)
    with db.write() as session:
        auth_crud.create_user(session, USER, PASSWORD, "viewer")
        _, engineer_key = auth_crud.create_api_key(session, "bench-upload", "engineer", created_by="bench")
    db.dispose()
    files = []
    for seed in range(n_uploads):
        path = tmp / f"upload-{seed}.h5"
        simulate_run(path, duration_s=2.0, fs=4000.0, seed=seed, with_forces=False)
        files.append(str(path))
    return run_id, viewer_key, engineer_key, files


def _serve(env: dict[str, str], port: int, workers: int, log: Path) -> subprocess.Popen:
    proc = subprocess.Popen(
        [str(Path(sys.executable).with_name("trackvkf")), "serve", "--port", str(port), "--workers", str(workers),
         "--log-level", "warning"],
        cwd=ROOT, env=env, stdout=log.open("w"), stderr=subprocess.STDOUT, start_new_session=True,
    )
    import httpx

    deadline = time.time() + 120
    while time.time() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/api/v1/health", timeout=2).status_code == 200:
                return proc
        except httpx.HTTPError:
            pass
        if proc.poll() is not None:
            raise RuntimeError(f"server exited: {log.read_text()[-2000:]}")
        time.sleep(0.5)
    raise RuntimeError("server did not start")


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def _etags(base_url: str, key: str, run_id: int) -> dict[str, str]:
    import httpx

    out = {}
    for wheel in ("11", "12", "41", "42"):
        r = httpx.get(f"{base_url}/api/v1/runs/{run_id}/profile", headers={"Authorization": f"Bearer {key}"},
                      params={"wheel": wheel, "max_points": MAX_POINTS, "columns": COLUMNS, "layout": "columns"},
                      timeout=60)
        r.raise_for_status()
        out[wheel] = r.headers["etag"]
    return out


def _run_wrk(base_url: str, scenario: str, key: str, run_id: int, km: float, etags: dict[str, str],
             connections: int, duration: int, tmp: Path) -> dict:
    lua = tmp / f"{scenario}.lua"
    table = "{" + ", ".join(f'["{w}"] = {json.dumps(e)}' for w, e in etags.items()) + "}"
    lua.write_text(_LUA % {"scenario": scenario, "key": key, "run_id": run_id, "km": km, "etags": table,
                           "columns": COLUMNS, "max_points": MAX_POINTS})
    out = subprocess.run(
        ["wrk", "-t2", f"-c{connections}", f"-d{duration}s", "--timeout", "10s", "-s", str(lua),
         f"{base_url}/"], capture_output=True, text=True, check=True,
    ).stdout
    line = next(x for x in out.splitlines() if x.startswith("WRKJSON "))
    return json.loads(line.removeprefix("WRKJSON "))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--km", type=float, default=100.0, help="run length, km")
    parser.add_argument("--workers", type=int, default=None, help="API processes (default: one per core)")
    parser.add_argument("--connections", type=int, default=50)
    parser.add_argument("--duration", type=int, default=30, help="seconds per scenario")
    parser.add_argument("--scenario", choices=["map", "zoom", "revalidate", "all"], default="all")
    parser.add_argument("--database", choices=["sqlite", "postgresql"], default="sqlite")
    parser.add_argument("--keep", action="store_true", help="keep the work directory")
    parser.add_argument("--probe", nargs=4, metavar=("URL", "KEY", "OUT", "STOP"), help=argparse.SUPPRESS)
    parser.add_argument("--files", nargs="*", default=[], help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.probe:
        _probe(args.probe[0], args.probe[1], args.files, args.probe[2], args.probe[3])
        return 0
    if shutil.which("wrk") is None:
        print("wrk is not installed: apt-get install wrk", file=sys.stderr)
        return 2

    from app.cli.service import default_api_workers

    workers = args.workers or default_api_workers()
    scenarios = ["map", "zoom", "revalidate"] if args.scenario == "all" else [args.scenario]
    tmp = Path(tempfile.mkdtemp(prefix="bench-display-load-"))
    cluster = None
    server = None
    try:
        if args.database == "postgresql":
            from tests.pg_cluster import PgCluster

            cluster = PgCluster().init()
            database_url = cluster.url
        else:
            database_url = f"sqlite:///{tmp / 'db.sqlite'}"
        n_uploads = args.duration * len(scenarios) // 3 + 2
        run_id, viewer_key, engineer_key, files = _prepare(database_url, args.km, tmp, n_uploads)
        port = _free_port()
        base_url = f"http://127.0.0.1:{port}"
        server = _serve(_env(database_url, tmp / "runs"), port, workers, tmp / "server.log")
        etags = _etags(base_url, viewer_key, run_id)  # also warms each process' cache a little
        print(f"\n{args.database}, {workers} API process(es), {args.connections} connections, "
              f"{args.duration} s per scenario, {args.km:g} km run, max_points={MAX_POINTS}, "
              f"columns={COLUMNS}, layout=columns, gzip; load average before: {os.getloadavg()[0]:.1f}")
        print("\n| scenario | req/s | p50 ms | p90 ms | p99 ms | max ms | 5xx | other errors | MB/s | "
              "login max s | upload max s | writes | API CPU ms per request | API RSS MB | machine busy % | "
              "stolen CPU s | load avg |")
        print("|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|")
        for scenario in scenarios:
            probe_out, stop = tmp / f"probe-{scenario}.json", tmp / f"stop-{scenario}"
            probe = subprocess.Popen(
                [sys.executable, __file__, "--probe", base_url, engineer_key, str(probe_out), str(stop),
                 "--files", *files[: args.duration // 3 + 2]], cwd=ROOT)
            busy0, steal0 = _cpu_times()
            api0 = _group_cpu_s(server.pid)
            t0 = time.perf_counter()
            result = _run_wrk(base_url, scenario, viewer_key, run_id, args.km, etags, args.connections,
                              args.duration, tmp)
            wall = time.perf_counter() - t0
            busy1, steal1 = _cpu_times()
            api1 = _group_cpu_s(server.pid)
            stop.touch()
            probe.wait(120)
            writes = json.loads(probe_out.read_text())
            files = files[args.duration // 3 + 2:]
            logins = [w["s"] for w in writes if w["kind"] == "login"]
            uploads = [w["s"] for w in writes if w["kind"] == "upload"]
            bad_writes = [w for w in writes if w["status"] >= 300]
            n5xx = sum(k for s, k in result["statuses"].items() if int(s) >= 500)
            other = sum(result["errors"].values()) - result["errors"]["status"]
            rate = result["requests"] / (result["duration_us"] / 1e6)
            print(f"| {scenario} | {rate:.0f} | {result['p50_ms']:.0f} | {result['p90_ms']:.0f} | "
                  f"{result['p99_ms']:.0f} | {result['max_ms']:.0f} | {n5xx} | {other} | "
                  f"{result['bytes'] / (result['duration_us'] / 1e6) / 1e6:.1f} | "
                  f"{max(logins):.2f} | {max(uploads) if uploads else float('nan'):.2f} | "
                  f"{len(logins)} logins + {len(uploads)} uploads"
                  f"{f', {len(bad_writes)} failed' if bad_writes else ''} | "
                  f"{1000 * (api1 - api0) / max(result['requests'], 1):.1f} | {_group_rss_mb(server.pid):.0f} | "
                  f"{100 * (busy1 - busy0) / (wall * os.cpu_count()):.0f} | {steal1 - steal0:.1f} | "
                  f"{os.getloadavg()[0]:.1f} |",
                  flush=True)
            if bad_writes:
                print(f"  failed writes: {bad_writes[:5]}")
            if logins:
                print(f"  login median {statistics.median(logins):.2f} s; statuses {result['statuses']}")
    finally:
        if server is not None:
            _stop(server)
        if cluster is not None:
            cluster.destroy()
        if args.keep:
            print(f"work directory: {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
