"""Issue 18 item 5: an upload cut off by a killed API is swept at the next start-up.

The sweep used to remove only uploads older than 6 h, so the partial upload of
an API killed mid-upload survived restarts (the README said "swept at
start-up"). Now every upload directory no live process owns (``flock``) goes,
and the uploads other API processes are receiving stay.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import httpx

from app.core.runstore import RunStore
from tests.e2e.conftest import Service, _free_port, running_service
from tests.faults.support import hdf5_run

MIB = 1 << 20

_HOLD_AN_UPLOAD = textwrap.dedent(
    """
    import sys, time
    from app.core.runstore import RunStore
    store = RunStore(sys.argv[1])
    path = store.new_upload_dir()
    (path / "upload").write_bytes(b"partial")
    print(path, flush=True)
    time.sleep(600)
    """
)


def test_sweep_removes_what_no_live_process_owns(tmp_path):
    store = RunStore(tmp_path / "runs")
    owner = subprocess.Popen(
        [sys.executable, "-c", _HOLD_AN_UPLOAD, str(store.root)], stdout=subprocess.PIPE, text=True,
        cwd=Path(__file__).resolve().parents[2],
    )
    try:
        held = Path(owner.stdout.readline().strip())
        mine = store.new_upload_dir()
        orphan = store.uploads_dir / "0123456789abcdef"  # left by a process that is gone
        orphan.mkdir()
        (orphan / "upload.h5").write_bytes(b"x" * 1000)
        assert store.sweep_uploads(older_than_s=3600) == 1  # young, but nobody owns it
        assert not orphan.exists()
        assert held.is_dir() and mine.is_dir()  # owned by a live process (another one, and this one)
        owner.send_signal(signal.SIGKILL)
        owner.wait()
        assert store.sweep_uploads(older_than_s=3600) == 1  # its owner died: no lock any more
        assert not held.exists() and mine.is_dir()
        store.release_upload_dir(mine)
        assert not mine.exists()
        assert list(store.uploads_dir.iterdir()) == []
    finally:
        if owner.poll() is None:
            owner.kill()
            owner.wait()
        owner.stdout.close()


def _slow_body(path: Path, started: threading.Event, pause_s: float,
               hold: threading.Event | None = None) -> object:
    """The file in quarter-MiB pieces, ``pause_s`` apart; with ``hold``, the rest waits
    after the first piece until ``hold`` is set (an upload that outlives whatever the
    test does meanwhile, however slow the machine)."""
    data = path.read_bytes()
    for i in range(0, len(data), MIB // 4):
        yield data[i : i + MIB // 4]
        started.set()
        if hold is not None:
            assert hold.wait(120), "the test never released the upload"
        time.sleep(pause_s)


def _post_slowly(base_url: str, key: str, path: Path, started: threading.Event, pause_s: float,
                 out: dict, hold: threading.Event | None = None) -> None:
    try:
        r = httpx.post(
            f"{base_url}/api/v1/runs", params={"filename": path.name},
            content=_slow_body(path, started, pause_s, hold),
            headers={"Authorization": f"Bearer {key}", "content-type": "application/x-hdf5"},
            timeout=120,
        )
        out["status"] = r.status_code
        out["body"] = r.text
    except httpx.HTTPError as exc:
        out["error"] = repr(exc)


def _upload_files(store: Path) -> list[Path]:
    uploads = store / ".uploads"
    return sorted(p for p in uploads.rglob("*") if p.is_file()) if uploads.is_dir() else []


def _wait_for(predicate, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def test_partial_upload_of_a_killed_api_is_swept_at_restart_but_not_another_apis(tmp_path):
    with running_service(tmp_path / "svc") as svc:
        other = Service(
            base_url=f"http://127.0.0.1:{_free_port()}", env=svc.env, backend=svc.backend,
            workdir=svc.workdir, database_url=svc.database_url, run_store=svc.run_store, api_key=svc.api_key,
        )
        release = threading.Event()  # lets the live upload go on once the restart is checked
        other.start_api()
        try:
            # an upload in progress on the other API process, held after its first piece until the restart
            # is checked (then the rest goes at once)
            slow = hdf5_run(tmp_path, n=120_000)
            started, result = threading.Event(), {}
            live = threading.Thread(
                target=_post_slowly,
                args=(other.base_url, svc.api_key, slow, started, 0.0, result, release),
            )
            live.start()
            assert started.wait(30)
            # an upload cut off by SIGKILL of the first API process
            cut = hdf5_run(tmp_path, n=200_000)
            started_cut = threading.Event()
            dying = threading.Thread(
                target=_post_slowly, args=(svc.base_url, svc.api_key, cut, started_cut, 0.5, {})
            )
            dying.start()
            assert started_cut.wait(30)
            _wait_for(lambda: len(_upload_files(svc.run_store)) == 2)
            svc.kill_api()
            dying.join(60)
            leftovers = _upload_files(svc.run_store)
            assert len(leftovers) == 2  # the cut-off upload stays ... until the restart
            svc.start_api()
            remaining = _upload_files(svc.run_store)
            assert len(remaining) == 1 and remaining[0] in leftovers, (remaining, result)  # the live one
            release.set()
            live.join(120)
            assert result.get("status") == 201, result  # and it finished
            assert _upload_files(svc.run_store) == []
        finally:
            release.set()
            other.stop()
    assert os.path.isdir(svc.run_store)
