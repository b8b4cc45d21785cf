"""/metrics with several API processes (``trackvkf serve --workers 2``, prometheus-client's
multi-process mode): whichever process answers a scrape, it counts the requests every process
served; the counts start afresh with the service."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import pytest

from app.db import migrate
from tests.api.support import create_api_key

pytestmark = pytest.mark.timeout(300)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _health_count(text: str) -> float:
    m = re.search(r'^trackvkf_http_requests_total\{method="GET",route="/api/v1/health",status="200"\} (\S+)$',
                  text, re.M)
    return float(m.group(1)) if m else 0.0


def test_two_api_processes_are_counted_together(tmp_path):
    url = f"sqlite:///{tmp_path / 'db.sqlite'}"
    migrate.upgrade(url)
    key = create_api_key(url, "admin", "prometheus")
    metrics_dir = tmp_path / "metrics"
    metrics_dir.mkdir()
    (metrics_dir / "counter_999999.db").write_bytes(b"stale")  # left by an earlier service: removed
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("TRACKVKF_")}
    env.update(TRACKVKF_DATABASE_URL=url, TRACKVKF_RUN_STORE=str(tmp_path / "runs"),
               PROMETHEUS_MULTIPROC_DIR=str(metrics_dir))
    trackvkf = Path(sys.executable).with_name("trackvkf")
    log = open(tmp_path / "serve.log", "wb")
    proc = subprocess.Popen([str(trackvkf), "serve", "--port", str(port), "--workers", "2", "--log-level", "warning"],
                            env=env, cwd=tmp_path, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                if httpx.get(f"{base}/api/v1/health", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline and proc.poll() is None, (tmp_path / "serve.log").read_text()
            time.sleep(0.3)
        sent = 1
        with httpx.Client(base_url=base, timeout=10) as client, ThreadPoolExecutor(8) as pool:
            pids: set[str] = set()
            while len(pids) < 2 and sent < 2000:  # until both processes served some
                codes = list(pool.map(lambda _: client.get("/api/v1/health").status_code, range(50)))
                assert codes == [200] * 50
                sent += 50
                pids = {p.name.split("_")[-1].removesuffix(".db") for p in metrics_dir.glob("counter_*.db")}
                pids.discard(str(proc.pid))  # the supervising process (it serves nothing)
            assert len(pids) == 2, pids  # two serving processes, and the stale file gone
            assert "999999" not in pids
            auth = {"Authorization": f"Bearer {key}"}
            counts = {_health_count(client.get("/metrics", headers=auth).text) for _ in range(10)}
        assert counts == {float(sent)}, (counts, sent)
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()
