"""Service benchmark (issue 3): a simulated run from upload to stored profiles.

Usage::

    .venv/bin/python bench/bench_service.py                   # 30-minute run, 4 Z + 4 Q @ 24 kHz
    .venv/bin/python bench/bench_service.py --minutes 3       # shorter
    .venv/bin/python bench/bench_service.py --chunk-processes 1

Simulates the run once (cached under ``--workdir``, not timed), starts the real
service (uvicorn API + one worker, ``TRACKVKF_WORKER_CHUNK_PROCESSES`` chunk
processes) on a fresh SQLite database, uploads the file over HTTP and polls the
job until it is done. Reports the wall time of upload, processing and the whole,
and the peak resident memory of the API and of the worker (the sum over the
worker and its chunk processes, sampled every 0.2 s from /proc). Prints a
Markdown table row for BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _tree_rss_mb(pid: int, tree: bool = True) -> float:
    """Proportional set size of a process (and its descendants), MB (Linux /proc)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as fh:
                ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
        except OSError:
            continue
        children.setdefault(ppid, []).append(int(entry))
    total, todo = 0.0, [pid]
    while todo:
        p = todo.pop()
        if tree:
            todo.extend(children.get(p, []))
        try:
            # PSS: shared pages (forkserver children share the imported modules)
            # are split between the processes that map them, so the sum is real use
            with open(f"/proc/{p}/smaps_rollup") as fh:
                for line in fh:
                    if line.startswith("Pss:"):
                        total += int(line.split()[1]) / 1024
        except OSError:
            pass
    return total


class PeakSampler(threading.Thread):
    """Samples the RSS of process trees until stopped; keeps the maxima."""

    def __init__(self, pids: dict[str, int], interval: float = 0.2) -> None:
        super().__init__(daemon=True)
        self.pids, self.interval = pids, interval
        self.peak = dict.fromkeys(pids, 0.0) | {f"{name}_main": 0.0 for name in pids}
        self._stop_event = threading.Event()

    def run(self) -> None:
        while not self._stop_event.is_set():
            for name, pid in self.pids.items():
                self.peak[name] = max(self.peak[name], _tree_rss_mb(pid))
                self.peak[f"{name}_main"] = max(self.peak[f"{name}_main"], _tree_rss_mb(pid, tree=False))
            self._stop_event.wait(self.interval)

    def stop(self) -> dict[str, float]:
        self._stop_event.set()
        self.join()
        return self.peak


def simulate(path: Path, minutes: float) -> None:
    if path.exists():
        return
    from app.simulate.run import simulate_run

    path.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    simulate_run(path, duration_s=60.0 * minutes, fs=24_000.0, seed=7, with_forces=True)
    print(f"simulated {minutes:g} min in {time.perf_counter() - t0:.0f} s -> {path}", file=sys.stderr)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--chunk-processes", type=int, default=2)
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/trackvkf-bench-service"))
    args = parser.parse_args()

    run_file = args.workdir / f"sim-{args.minutes:g}min.h5"
    simulate(run_file, args.minutes)
    case = args.workdir / f"case-{os.getpid()}"
    case.mkdir(parents=True)
    db_url = f"sqlite:///{case / 'bench.sqlite'}"
    from app.db import migrate

    migrate.upgrade(db_url)
    from app.db import auth_crud
    from app.db.session import Database

    db = Database(db_url)
    with db.write() as session:
        _, api_key = auth_crud.create_api_key(session, "bench", "engineer", created_by="bench")
    db.dispose()
    env = {k: v for k, v in os.environ.items() if not k.startswith("TRACKVKF_")}
    env.update(
        TRACKVKF_DATABASE_URL=db_url,
        TRACKVKF_RUN_STORE=str(case / "runs"),
        TRACKVKF_WORKER_POLL_INTERVAL_S="0.2",
        TRACKVKF_WORKER_CHUNK_PROCESSES=str(args.chunk_processes),
        TRACKVKF_LOG_LEVEL="WARNING",
        PYTHONPATH=str(ROOT),
    )
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    logs = open(case / "service.log", "wb")
    api = subprocess.Popen(
        [sys.executable, "-m", "uvicorn", "--factory", "app.main:create_app", "--host", "127.0.0.1",
         "--port", str(port), "--log-level", "warning"],
        env=env, cwd=case, stdout=logs, stderr=subprocess.STDOUT, start_new_session=True,
    )
    worker = subprocess.Popen([sys.executable, "-m", "worker"], env=env, cwd=case, stdout=logs,
                              stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(f"{base}/api/v1/health", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError("API did not come up")
            time.sleep(0.2)
        sampler = PeakSampler({"api": api.pid, "worker": worker.pid})
        sampler.start()
        headers = {"Authorization": f"Bearer {api_key}"}
        with httpx.Client(base_url=base, timeout=None, headers=headers) as client:
            t0 = time.perf_counter()
            with open(run_file, "rb") as fh:
                resp = client.post("/api/v1/runs", files={"file": (run_file.name, fh, "application/x-hdf5")})
            resp.raise_for_status()
            t_upload = time.perf_counter() - t0
            run = resp.json()
            job_id = run["latest_job"]["id"]
            while True:
                job = client.get(f"/api/v1/jobs/{job_id}").json()
                if job["status"] in ("done", "failed", "cancelled"):
                    break
                time.sleep(0.5)
            t_total = time.perf_counter() - t0
        peak = sampler.stop()
        if job["status"] != "done":
            raise RuntimeError(f"job {job['status']}: {job['error']}")
        n_channels = len([c for c in run["summary"]["channels"] if c[0] in "ZQ"])
        result = {
            "minutes": args.minutes,
            "channels": n_channels,
            "file_mb": run_file.stat().st_size / 1e6,
            "chunk_processes": args.chunk_processes,
            "upload_s": round(t_upload, 1),
            "processing_s": round(t_total - t_upload, 1),
            "total_s": round(t_total, 1),
            "n_chunks": job["n_chunks"],
            "api_peak_mb": round(peak["api"]),
            "worker_peak_mb": round(peak["worker"]),
            "worker_main_process_peak_mb": round(peak["worker_main"]),
        }
        print(json.dumps(result))
        print(
            f"| {args.minutes:g} min, {n_channels} channels @ 24 kHz ({result['file_mb']:.0f} MB HDF5) "
            f"| {args.chunk_processes} | {result['upload_s']} | {result['processing_s']} | {result['total_s']} "
            f"| {result['api_peak_mb']} | {result['worker_peak_mb']} |"
        )
    finally:
        for proc in (worker, api):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in (worker, api):
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
        logs.close()


if __name__ == "__main__":
    main()
