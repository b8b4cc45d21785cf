"""Issue 24 defect 10: a worker killed right after the publish commit left
``runs/<id>/jobs/<job>/`` until the run's next job ended. A real worker process is killed
(SIGKILL, by itself) at the instant after the commit that publishes its job, before it removes
the job's folder; the next worker's start-up sweep removes that folder, and leaves alone the
folder of a job that is still queued (it resumes from its chunks)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from app.core.runstore import RunStore
from tests.faults.support import hdf5_run, upload_file

pytestmark = pytest.mark.timeout(300)

#: a worker that kills itself where the job's files would be removed, right after the publish commit
_KILLED_AFTER_PUBLISH = """
import os, signal, sys
from app.settings import get_settings
from worker import runner, steps
steps.discard_job_files = lambda *a, **k: os.kill(os.getpid(), signal.SIGKILL)
runner.run_worker(get_settings(), once=True)
"""


def _env(settings) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("TRACKVKF_")}
    env.update(TRACKVKF_DATABASE_URL=settings.database_url, TRACKVKF_RUN_STORE=str(settings.run_store),
               TRACKVKF_WORKER_POLL_INTERVAL_S="0.2", TRACKVKF_WORKER_HEARTBEAT_S="0.5",
               TRACKVKF_WORKER_STALE_AFTER_S="3", TRACKVKF_LOG_LEVEL="INFO")
    return env


def test_the_start_up_sweep_removes_the_folder_of_a_job_published_by_a_killed_worker(client, tmp_path):
    settings = client.settings
    run = upload_file(client, hdf5_run(tmp_path, n=40_000)).json()
    run_id, job_id = run["id"], run["latest_job"]["id"]
    store = RunStore(settings.run_store)

    killed = subprocess.run([sys.executable, "-c", _KILLED_AFTER_PUBLISH], env=_env(settings), cwd=tmp_path,
                            capture_output=True, text=True, timeout=240)
    assert killed.returncode == -9, killed.stderr[-3000:]
    assert client.get(f"/api/v1/jobs/{job_id}").json()["status"] == "done"  # committed before the kill
    assert store.job_ids_with_files(run_id) == [job_id]  # ... and its folder left behind
    assert any(store.job_dir(run_id, job_id).iterdir())

    # a reprocess job waits in the queue with a chunk already done: its folder must stay
    queued = client.post(f"/api/v1/runs/{run_id}/jobs", json={}).json()["id"]
    kept = store.chunk_path(run_id, queued, 0)
    kept.parent.mkdir(parents=True)
    kept.write_bytes(b"chunk")

    # the next worker process starts: its background start (the sweep) before any job is claimed
    started = subprocess.run(
        [sys.executable, "-c",
         "from app.settings import get_settings\n"
         "from app.core.logging import configure_logging\n"
         "from worker.background import Background\n"
         "configure_logging('INFO')\n"
         "Background(get_settings(), 'local').start().stop()\n"],
        env=_env(settings), cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert started.returncode == 0, started.stderr[-3000:]
    assert "removed 1 leftover job folder" in started.stderr
    assert not store.job_dir(run_id, job_id).exists()
    assert store.job_ids_with_files(run_id) == [queued] and kept.read_bytes() == b"chunk"
    assert sorted(p.name for p in store.run_dir(run_id).iterdir()) == ["jobs", "run.h5"]
