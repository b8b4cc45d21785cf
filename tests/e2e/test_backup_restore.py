"""Issue 24 defect 7: no backup and restore (a plain copy of the SQLite file without its WAL was
corrupt 1 time in 5). Over the real service in both modes (SQLite + local worker, PostgreSQL +
Procrastinate worker, pg_dump/pg_restore): backups are taken with ``trackvkf backup`` while a
worker processes three runs; one taken mid-way is restored with ``trackvkf restore`` into a fresh
database and run store, where every run, job, profile and condition row of the snapshot is found,
every run file matches its checksum, and a worker on the restored service finishes the jobs that
were waiting with the same profiles as the original service. A corrupted backup is refused
before anything is touched, and a target that holds data needs --force."""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from sqlalchemy import func, select

from app.db.models import ConditionRun, Job, JobStatus, ProfileBin, Run, SegmentCondition, WheelOOR
from app.db.session import Database
from tests.api import runfiles
from tests.e2e.conftest import running_service
from tests.e2e.support import profile, wait_final
from tests.faults.support import hdf5_run

pytestmark = pytest.mark.timeout(900)

N_RUNS = 3  # a backup before, one mid-way (0 < done < N_RUNS) and one after the worker wrote; the restored worker finishes the rest


def _cli(args: list[str], database_url: str, run_store: Path, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("TRACKVKF_")}
    env.update(TRACKVKF_DATABASE_URL=database_url, TRACKVKF_RUN_STORE=str(run_store))
    return subprocess.run([str(Path(sys.executable).with_name("trackvkf")), *args], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def _rows(database_url: str) -> dict:
    """What the test checks in a database: runs, jobs by status, profile and condition rows."""
    db = Database(database_url)
    try:
        with db.read() as s:
            return {
                "runs": {i: p for i, p in s.execute(select(Run.id, Run.file_path))},
                "jobs": {i: st for i, st in s.execute(select(Job.id, Job.status))},
                "profile_rows": dict(s.execute(select(ProfileBin.job_id, func.count()).group_by(ProfileBin.job_id)).all()),
                "wheel_rows": dict(s.execute(select(WheelOOR.run_id, func.count()).group_by(WheelOOR.run_id)).all()),
                "condition_runs": set(s.scalars(select(ConditionRun.run_id))),
                "segment_rows": int(s.scalar(select(func.count()).select_from(SegmentCondition))),
            }
    finally:
        db.dispose()


def test_backup_while_the_worker_writes_then_restore(service, tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    with service.client(timeout=120) as client:
        run_ids = []
        for i in range(N_RUNS):
            md = runfiles.metadata(sample_rate_hz=None, start_time=(
                dt.datetime(2026, 3, 2, 8, tzinfo=dt.UTC) + dt.timedelta(days=i)).isoformat())
            path = hdf5_run(work, md=md, n=200_000)
            with open(path, "rb") as fh:
                r = client.post("/api/v1/runs", files={"file": (path.name, fh)})
            assert r.status_code == 201, r.text
            run_ids.append(r.json()["id"])
        jobs = [client.get(f"/api/v1/runs/{i}").json()["latest_job"]["id"] for i in run_ids]

        service.start_worker()
        backups: list[tuple[Path, int]] = []  # (backup, jobs done when it was started)
        while True:
            done = sum(client.get(f"/api/v1/jobs/{j}").json()["status"] == "done" for j in jobs)
            dest = tmp_path / f"backup-{len(backups)}"
            r = _cli(["backup", str(dest)], service.database_url, service.run_store, tmp_path)
            assert r.returncode == 0, r.stderr
            backups.append((dest, done))
            if done == N_RUNS:
                break
        for j in jobs:
            assert wait_final(client, j, service)["status"] == "done"
        originals = {i: profile(client, i) for i in run_ids}

    mid = next((b for b, done in backups if 0 < done < N_RUNS), None) or backups[0][0]
    print(f"{len(backups)} backups while the worker ran (jobs done at each start: {[d for _, d in backups]}); "
          f"restoring {mid.name}")
    manifest = json.loads((mid / "manifest.json").read_text())
    assert manifest["database"] == service.backend and manifest["revision"]
    assert sorted(f["run_id"] for f in manifest["files"]) == run_ids  # every run, its file
    for f in manifest["files"]:
        assert hashlib.sha256((mid / "runs" / f["path"]).read_bytes()).hexdigest() == f["sha256"]

    # restore into a fresh database and run store of the same kind
    if service.backend == "sqlite":
        target_url = f"sqlite:///{tmp_path / 'restored.sqlite'}"
    else:
        target_url = service.pg.create_database()
    target_store = tmp_path / "restored-runs"
    r = _cli(["restore", str(mid)], target_url, target_store, tmp_path)
    assert r.returncode == 0, r.stderr + r.stdout
    restored = _rows(target_url)
    assert sorted(restored["runs"]) == run_ids
    for run_id, rel in restored["runs"].items():
        f = next(f for f in manifest["files"] if f["run_id"] == run_id)
        assert rel == f["path"]
        assert hashlib.sha256((target_store / rel).read_bytes()).hexdigest() == f["sha256"]
    counts = manifest["counts"]
    assert len(restored["jobs"]) == counts["jobs"] and sum(restored["profile_rows"].values()) == counts["profile_bins"]
    assert restored["segment_rows"] == counts["segment_condition"] and len(restored["condition_runs"]) == counts[
        "condition_runs"]
    done_jobs = [j for j, st in restored["jobs"].items() if st == JobStatus.DONE]
    for job_id in done_jobs:  # a done job's rows are all there: profiles, wheels, condition
        assert restored["profile_rows"].get(job_id, 0) > 0
    done_runs = {run_id for run_id, job_id in zip(run_ids, jobs, strict=True) if job_id in done_jobs}
    assert done_runs <= set(restored["wheel_rows"]) and done_runs <= restored["condition_runs"]
    assert set(restored["jobs"].values()) <= {JobStatus.DONE, JobStatus.QUEUED}  # running ones requeued

    # the restored service finishes what waited, with the same results
    (tmp_path / "svc2").mkdir()
    with running_service(tmp_path / "svc2", target_url, backend=service.backend, pg=service.pg,
                         run_store=target_store) as svc2:
        svc2.start_worker()
        with svc2.client(timeout=120) as client:
            for j in jobs:
                assert wait_final(client, j, svc2)["status"] == "done"
            for run_id in run_ids:
                got = profile(client, run_id)
                cols = ["wheel", "bin", "sleeper_amp", "n_samples"]
                assert got[cols].equals(originals[run_id][cols]), run_id
    assert _rows(target_url)["condition_runs"] == set(run_ids)


def test_a_damaged_backup_is_refused_and_a_full_target_needs_force(client, tmp_path):
    settings = client.settings
    path = hdf5_run(tmp_path, n=20_000)
    assert client.post("/api/v1/runs", files={"file": (path.name, path.read_bytes())}).status_code == 201
    dest = tmp_path / "b"
    r = _cli(["backup", str(dest)], settings.database_url, settings.run_store, tmp_path)
    assert r.returncode == 0, r.stderr
    assert _cli(["backup", str(dest)], settings.database_url, settings.run_store, tmp_path).returncode == 1

    # into the service's own (full) database and store: refused without --force
    r = _cli(["restore", str(dest)], settings.database_url, settings.run_store, tmp_path)
    assert r.returncode == 1 and "--force" in r.stderr
    r = _cli(["restore", "--verify-only", str(dest)], settings.database_url, settings.run_store, tmp_path)
    assert r.returncode == 0 and "verified" in r.stdout

    target_url, target_store = f"sqlite:///{tmp_path / 't.sqlite'}", tmp_path / "t-runs"
    (run_file,) = (dest / "runs").rglob("*.h5")
    data = bytearray(run_file.read_bytes())
    data[len(data) // 2] ^= 0xFF
    run_file.write_bytes(bytes(data))
    r = _cli(["restore", str(dest)], target_url, target_store, tmp_path)
    assert r.returncode == 1 and "checksum" in r.stderr
    assert not Path(tmp_path / "t.sqlite").exists() and not target_store.exists()  # nothing touched
    data[len(data) // 2] ^= 0xFF
    run_file.write_bytes(bytes(data))

    db_file = dest / "database.sqlite"
    raw = bytearray(db_file.read_bytes())
    page = int.from_bytes(raw[16:18], "big")
    for start in range(2 * page, len(raw), page):  # every b-tree page header after the schema page
        raw[start] = 0x07  # not a page type
    db_file.write_bytes(bytes(raw))
    r = _cli(["restore", str(dest)], target_url, target_store, tmp_path)
    assert r.returncode == 1 and ("integrity" in r.stderr or "malformed" in r.stderr), r.stderr
    assert not target_store.exists()


def test_force_keeps_the_replaced_database_and_run_store_aside(client, tmp_path):
    settings = client.settings
    path = hdf5_run(tmp_path, n=20_000)
    assert client.post("/api/v1/runs", files={"file": (path.name, path.read_bytes())}).status_code == 201
    dest = tmp_path / "b"
    assert _cli(["backup", str(dest)], settings.database_url, settings.run_store, tmp_path).returncode == 0
    other = hdf5_run(tmp_path, n=20_000)
    assert client.post("/api/v1/runs", files={"file": (other.name, other.read_bytes())}).status_code == 201
    client.app.state.db.dispose()
    r = _cli(["restore", "--force", str(dest)], settings.database_url, settings.run_store, tmp_path)
    assert r.returncode == 0, r.stderr
    assert "previous run store" in r.stdout and "previous database" in r.stdout
    aside = [p for p in Path(settings.run_store).parent.iterdir() if ".before-restore-" in p.name]
    stores = [p for p in aside if p.is_dir()]
    assert len(stores) == 1 and sorted(p.name for p in stores[0].iterdir() if p.name.isdigit()) == ["1", "2"]
    (old_db,) = [p for p in aside if p.is_file() and p.name.startswith("db.sqlite")]
    assert len(_rows(f"sqlite:///{old_db}")["runs"]) == 2  # the replaced database, kept whole
    assert len(_rows(settings.database_url)["runs"]) == 1
    # ids handed out after the restore never repeat those of the lost period (run 2 here)
    third = hdf5_run(tmp_path, n=20_000)
    r = client.post("/api/v1/runs", files={"file": (third.name, third.read_bytes())})
    assert r.status_code == 201 and r.json()["id"] > 1_000_000 and r.json()["latest_job"]["id"] > 1_000_000
