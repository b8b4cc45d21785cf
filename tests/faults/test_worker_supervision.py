"""Issue 18 item 10: a killed worker process of ``trackvkf worker --processes N`` is replaced.

``--processes 2`` ran with one child for minutes after a SIGKILL, and
``python -m worker.health`` still said healthy (the dead child's liveness file
looked fresh). Now the supervisor restarts children with a back-off and the
health check counts the processes that really run.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

_SUPERVISE = textwrap.dedent(
    """
    import sys
    from worker.supervisor import Supervisor
    child = [sys.executable, "-c", sys.argv[1]]
    sys.exit(Supervisor(child, int(sys.argv[2]), min_backoff_s=0.2, max_backoff_s=1.0,
                        healthy_after_s=30.0, poll_s=0.05).run())
    """
)
#: a child that lives until SIGTERM, then exits 0 (as a worker does)
_LIVE = "import signal, sys, time; signal.signal(signal.SIGTERM, lambda *a: sys.exit(0)); time.sleep(300)"


def _env(tmp: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("TRACKVKF_")}
    env["TMPDIR"] = str(tmp)  # liveness and status files of this test only
    return env


def _status(tmp: Path, pid: int) -> dict | None:
    try:
        return json.loads((tmp / f"trackvkf-workers-{pid}.json").read_text())
    except (FileNotFoundError, ValueError):
        return None


def _wait(predicate, timeout_s: float = 60.0):
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def test_a_killed_child_is_replaced_and_sigterm_stops_all(tmp_path):
    sup = subprocess.Popen([sys.executable, "-c", _SUPERVISE, _LIVE, "2"], cwd=ROOT, env=_env(tmp_path))
    try:
        first = _wait(lambda: (s := _status(tmp_path, sup.pid)) and len(s["pids"]) == 2 and s)
        victim = first["pids"][0]
        os.kill(victim, signal.SIGKILL)
        again = _wait(lambda: (s := _status(tmp_path, sup.pid)) and s["restarts"] == 1 and len(s["pids"]) == 2 and s)
        assert victim not in again["pids"] and first["pids"][1] in again["pids"]
        sup.send_signal(signal.SIGTERM)
        assert sup.wait(timeout=30) == 0
        for pid in again["pids"]:
            with pytest.raises(ProcessLookupError):
                os.kill(pid, 0)
        assert not (tmp_path / f"trackvkf-workers-{sup.pid}.json").exists()
    finally:
        if sup.poll() is None:
            sup.kill()


def test_children_dying_young_are_restarted_with_a_growing_back_off(tmp_path):
    stamps = tmp_path / "starts.txt"
    crash = f"open({str(stamps)!r}, 'a').write('x\\n'); raise SystemExit(3)"
    sup = subprocess.Popen(
        [sys.executable, "-c", _SUPERVISE, crash, "1"], cwd=ROOT, env=_env(tmp_path),
        stderr=subprocess.PIPE, text=True,
    )
    try:
        _wait(lambda: stamps.exists() and len(stamps.read_text().split()) >= 6, 60)
        # stop between two children (one just starting would be stopped by the signal: status 0):
        # every child started so far has exited and the next one waits for its back-off
        _wait(lambda: (s := _status(tmp_path, sup.pid)) is not None and not s["pids"]
              and s["restarts"] >= len(stamps.read_text().split()), 60)
    finally:
        sup.send_signal(signal.SIGTERM)
        code = sup.wait(timeout=30)
        log = sup.stderr.read()
        sup.stderr.close()
    pauses = [float(m) for m in re.findall(r"exited with status 3 .*; starting a new one in ([0-9.]+) s", log)]
    assert pauses[:5] == [0.2, 0.4, 0.8, 1.0, 1.0], pauses  # doubling up to max_backoff_s
    assert code == 3  # the status of the children's last run


def test_health_counts_the_processes_that_run(tmp_path):
    """``python -m worker.health`` with a supervisor of two children that touch their
    liveness files: 2/2 (exit 0); a child SIGKILL-ed: 1/2 (exit 1) until it is replaced."""
    touch = (
        "import os, signal, sys, tempfile, time; signal.signal(signal.SIGTERM, lambda *a: sys.exit(0))\n"
        "p = os.path.join(tempfile.gettempdir(), f'trackvkf-worker-{os.getpid()}.alive')\n"
        # a replacement (started after the test wrote 'killed') touches only once the test has
        # seen the 1/2 and written 'go' (however long a health check takes on a loaded machine)
        "d = tempfile.gettempdir()\n"
        "replaced = os.path.exists(os.path.join(d, 'killed'))\n"
        "time.sleep(float(os.environ.get('START_DELAY', '0')))\n"
        "while replaced and not os.path.exists(os.path.join(d, 'go')):\n    time.sleep(0.1)\n"
        "while True:\n    open(p, 'a').close(); os.utime(p); time.sleep(0.2)\n"
    )
    env = _env(tmp_path) | {"TRACKVKF_WORKER_STALE_AFTER_S": "30", "START_DELAY": "2"}

    def health() -> tuple[int, str]:
        done = subprocess.run([sys.executable, "-m", "worker.health"], cwd=ROOT, env=env,
                              capture_output=True, text=True, check=False)
        return done.returncode, done.stdout.strip()

    assert health() == (1, "0/1 worker processes alive")  # nothing runs
    sup = subprocess.Popen([sys.executable, "-c", _SUPERVISE, touch, "2"], cwd=ROOT, env=env)
    try:
        _wait(lambda: health() == (0, "2/2 worker processes alive"), 60)
        victim = _status(tmp_path, sup.pid)["pids"][0]
        (tmp_path / "killed").touch()
        os.kill(victim, signal.SIGKILL)
        _wait(lambda: health() == (1, "1/2 worker processes alive"), 60)  # its fresh file no longer counts
        (tmp_path / "go").touch()
        _wait(lambda: health() == (0, "2/2 worker processes alive"), 60)  # replaced
        assert victim not in _status(tmp_path, sup.pid)["pids"]
    finally:
        sup.send_signal(signal.SIGTERM)
        assert sup.wait(timeout=30) == 0


def test_trackvkf_worker_processes_2_on_postgres(pg_cluster, tmp_path):
    """The real thing: ``python -m worker --processes 2`` (Procrastinate workers)."""
    if isinstance(pg_cluster, str):
        pytest.skip(pg_cluster)
    from app.db import migrate

    url = pg_cluster.create_database()
    migrate.upgrade(url)
    env = _env(tmp_path) | {
        "TRACKVKF_DATABASE_URL": url, "TRACKVKF_RUN_STORE": str(tmp_path / "runs"),
        "TRACKVKF_WORKER_HEARTBEAT_S": "0.5", "TRACKVKF_WORKER_STALE_AFTER_S": "5",
    }

    def health() -> tuple[int, str]:
        done = subprocess.run([sys.executable, "-m", "worker.health"], cwd=ROOT, env=env,
                              capture_output=True, text=True, check=False)
        return done.returncode, done.stdout.strip()

    sup = subprocess.Popen([sys.executable, "-m", "worker", "--processes", "2"], cwd=ROOT, env=env)
    try:
        _wait(lambda: health() == (0, "2/2 worker processes alive"), 120)
        victim = _status(tmp_path, sup.pid)["pids"][1]
        os.kill(victim, signal.SIGKILL)
        _wait(lambda: health()[0] == 1, 10)
        _wait(lambda: health() == (0, "2/2 worker processes alive"), 120)
        assert victim not in _status(tmp_path, sup.pid)["pids"]
    finally:
        sup.send_signal(signal.SIGTERM)
        code = sup.wait(timeout=90)
    assert code == 0
