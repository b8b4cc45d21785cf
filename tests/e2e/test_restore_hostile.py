"""Issue 32 findings 2, 3 and 6: a backup is hostile input to ``trackvkf restore``.

A service with an uploaded run and a generated fleet history (runs without a file) is backed up
(``trackvkf backup`` once crashed on the file-less runs); tampered copies of the backup are then
restored with ``--force`` over the service itself. Each is refused with one ``error:`` line (no
traceback) before anything of the target is touched: a symbolic link under ``runs/`` together
with a manifest path through ``..`` (it once wrote a file outside the target), a database file
outside the backup, a manifest without ``files``, an empty or truncated database file, a
manifest whose row counts or revision differ from the snapshot's. SQLite and PostgreSQL where
the snapshot is read (a SQLite file opened read-only; a pg_dump archive streamed and counted).
A restore that fails after it touched the target puts the old database and run store back.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from sqlalchemy import func, select

from app.db.models import Run
from app.db.session import Database
from app.settings import Settings
from tests.faults.support import hdf5_run

pytestmark = pytest.mark.timeout(600)


def _cli(args: list[str], settings: Settings, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("TRACKVKF_")}
    env.update(TRACKVKF_DATABASE_URL=settings.database_url, TRACKVKF_RUN_STORE=str(settings.run_store))
    return subprocess.run([str(Path(sys.executable).with_name("trackvkf")), *args], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def _state(settings: Settings) -> tuple:
    """What a refused restore must leave as it was: the runs, the run store's files, the target's
    directory (no database or store renamed aside)."""
    db = Database(settings.database_url)
    try:
        with db.read() as s:
            runs = tuple(s.execute(select(Run.id, Run.file_path, Run.line_id).order_by(Run.id)).all())
            n = s.scalar(select(func.count()).select_from(Run))
    finally:
        db.dispose()
    store = Path(settings.run_store)
    files = tuple(sorted(str(p.relative_to(store)) for p in store.rglob("*") if p.is_file()))
    around = tuple(sorted(p.name for p in store.parent.iterdir()))
    return runs, n, files, around


@pytest.fixture
def backed_up(request, make_client, tmp_path):
    """(settings, backup directory) of a service holding an uploaded run and two fleet runs."""
    overrides = {}
    backend = getattr(request, "param", "sqlite")
    if backend == "postgresql":
        cluster = request.getfixturevalue("pg_cluster")
        if isinstance(cluster, str):
            pytest.skip(cluster)
        overrides["database_url"] = cluster.create_database()
    client = make_client(**overrides)
    settings = client.settings
    path = hdf5_run(tmp_path, n=20_000)
    assert client.post("/api/v1/runs", files={"file": (path.name, path.read_bytes())}).status_code == 201
    r = _cli(["simulate-fleet", "--runs", "2", "--length-km", "1", "--line-id", "FLEET-A"], settings, tmp_path)
    assert r.returncode == 0, r.stderr
    client.app.state.db.dispose()
    dest = tmp_path / "backup"
    r = _cli(["backup", str(dest)], settings, tmp_path)
    assert r.returncode == 0, r.stderr  # the fleet runs have no file: skipped, not a traceback
    manifest = json.loads((dest / "manifest.json").read_text())
    assert manifest["counts"]["runs"] == 3 and len(manifest["files"]) == 1
    return settings, dest, backend


def _tampered(dest: Path, tmp_path: Path, name: str) -> Path:
    copy = tmp_path / name
    shutil.copytree(dest, copy, symlinks=True)
    return copy


def _edit_manifest(backup: Path, change) -> None:
    path = backup / "manifest.json"
    manifest = json.loads(path.read_text())
    change(manifest)
    path.write_text(json.dumps(manifest))


def _refused(settings: Settings, backup: Path, cwd: Path, *words: str) -> str:
    before = _state(settings)
    r = _cli(["restore", "--force", str(backup)], settings, cwd)
    assert r.returncode == 1, r.stdout + r.stderr
    assert r.stderr.startswith("error: ") and "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    for w in words:
        assert w in r.stderr, r.stderr
    assert _state(settings) == before  # nothing of the target touched
    return r.stderr


@pytest.mark.parametrize("backed_up", ["sqlite", "postgresql"], indirect=True)
def test_tampered_snapshots_are_refused_before_the_target_is_touched(backed_up, tmp_path):
    settings, dest, backend = backed_up
    db_name = "database.sqlite" if backend == "sqlite" else "database.dump"

    counts = _tampered(dest, tmp_path, "counts")
    _edit_manifest(counts, lambda m: m["counts"].update(runs=m["counts"]["runs"] + 1))
    _refused(settings, counts, tmp_path, "row counts", "runs")

    revision = _tampered(dest, tmp_path, "revision")
    _edit_manifest(revision, lambda m: m.update(revision="0003_auth_audit"))
    _refused(settings, revision, tmp_path, "revision")

    empty = _tampered(dest, tmp_path, "empty")
    (empty / db_name).write_bytes(b"")
    _refused(settings, empty, tmp_path, db_name)

    truncated = _tampered(dest, tmp_path, "truncated")
    data = (dest / db_name).read_bytes()
    (truncated / db_name).write_bytes(data[: len(data) // 3])
    _refused(settings, truncated, tmp_path, db_name)

    no_files = _tampered(dest, tmp_path, "no-files")
    _edit_manifest(no_files, lambda m: m.pop("files"))
    _refused(settings, no_files, tmp_path, "files")


def test_paths_leaving_the_backup_are_refused(backed_up, tmp_path):
    settings, dest, _ = backed_up  # the paths are checked before the snapshot is read: one backend
    manifest = json.loads((dest / "manifest.json").read_text())
    (entry,) = manifest["files"]

    # a relative symlink under runs/ and a path through '..' that resolves back onto a real file:
    # the check once followed the link (and passed) while the copy wrote the literal path outside
    linked = _tampered(dest, tmp_path, "linked")
    (linked / "runs" / "d1" / "d2" / "d3").mkdir(parents=True)
    (linked / "runs" / "a").symlink_to("d1/d2/d3")
    shutil.copyfile(linked / "runs" / entry["path"], linked / "runs" / "x")
    _edit_manifest(linked, lambda m: m["files"].append({**entry, "run_id": entry["run_id"],
                                                          "path": "a/../../../x"}))
    _refused(settings, linked, tmp_path, "symbolic link")
    (linked / "runs" / "a").unlink()
    _refused(settings, linked, tmp_path, "'..'")
    outside = [p for p in tmp_path.rglob("x") if p.parent.name != "runs"]
    assert outside == []

    absolute = _tampered(dest, tmp_path, "absolute")
    _edit_manifest(absolute, lambda m: m["files"][0].update(path=str(absolute / "runs" / entry["path"])))
    _refused(settings, absolute, tmp_path, "absolute")

    elsewhere = _tampered(dest, tmp_path, "elsewhere")
    shutil.copyfile(dest / "database.sqlite", tmp_path / "other.sqlite")
    _edit_manifest(elsewhere, lambda m: m.update(database_file=str(tmp_path / "other.sqlite")))
    _refused(settings, elsewhere, tmp_path, "database_file")

    db_link = _tampered(dest, tmp_path, "db-link")
    (db_link / "database.sqlite").unlink()
    (db_link / "database.sqlite").symlink_to(tmp_path / "other.sqlite")
    _refused(settings, db_link, tmp_path, "symbolic link")

    # the untampered backup restores over the service, keeping its database and run store aside
    r = _cli(["restore", "--force", str(dest)], settings, tmp_path)
    assert r.returncode == 0, r.stderr
    assert "previous database" in r.stdout and "previous run store" in r.stdout
    aside = sorted(p.name for p in Path(settings.run_store).parent.iterdir() if ".before-restore-" in p.name)
    assert len(aside) == 2, aside


def test_a_failed_restore_puts_the_target_back(backed_up, tmp_path, monkeypatch):
    """A restore failing after it replaced the database (here: the upgrade reports a wrong revision)
    leaves the old database and run store in place."""
    settings, dest, _ = backed_up
    from app.db import migrate
    from app.operations import backup as ops

    # a target with other data than the backup's: one more run
    target = Settings(_env_file=None, database_url=f"sqlite:///{tmp_path / 'target.sqlite'}",
                      run_store=tmp_path / "target-runs")
    assert ops.restore(target, dest).n_files == 1
    db = Database(target.database_url)
    with db.write() as s:
        s.add(Run(sha256="f" * 64, file_path="", source_format="fleet", size_bytes=0, line_id="EXTRA", fs=1.0,
                  n_samples=0, duration_s=0.0, channels=[], meta={}))
    db.dispose()
    (Path(target.run_store) / "marker").write_text("old store")
    before = _state(target)
    monkeypatch.setattr(migrate, "current_revision", lambda url: "not-the-head")
    with pytest.raises(ops.BackupError, match="as it was before the restore"):
        ops.restore(target, dest, force=True)
    assert _state(target) == before
