"""Backup and restore of a trackvkf service: the database and the run store, consistent together.

``trackvkf backup DEST`` writes a new directory::

    DEST/manifest.json           what is in it: format, database kind, Alembic revision,
                                 row counts per table, every run file with size and sha256
    DEST/database.sqlite         SQLite: a snapshot by the online backup API
    DEST/database.dump           PostgreSQL: pg_dump --format=custom
    DEST/runs/<run_id>/<file>    the run files the snapshot's runs refer to

The database snapshot is taken first, without stopping the service (SQLite: the
online backup API copies one read transaction's view, writers go on in WAL
mode; PostgreSQL: ``pg_dump --snapshot`` of an exported REPEATABLE READ
snapshot, the same one the list of runs is read from). Then the run files
*of the snapshot's runs* are copied and hashed. Run files are immutable (a
metadata correction writes a new file name), so a file the snapshot refers to
is either still there or was removed with its run (deleted, or its metadata
corrected) after the snapshot: then the whole backup is taken again (up to
``attempts`` times), never one whose rows and files disagree. Chunk files of
running jobs are not backed up (a restored running job starts again from its
first chunk), nor uploads in progress (they were never committed).

``trackvkf restore SRC`` verifies the backup before it touches anything (the
sha256 of every run file, ``PRAGMA integrity_check`` of a SQLite snapshot,
``pg_restore --list`` of a dump, an Alembic revision this version knows), then
restores the database (SQLite: the snapshot replaces the database file, its
old ``-wal``/``-shm`` removed; PostgreSQL: ``pg_restore --clean``), upgrades it
to the Alembic head when the backup is older, and the run store (copied into a
staging directory, hashed again, then swapped in; an existing run store is
kept aside as ``<run_store>.before-restore-<time>``). Finally it checks the
restored database's row counts against the manifest and requeues the jobs that
were running when the backup was taken. The service must be stopped during a
restore; a target that holds data is only overwritten with ``force``.
docs/operations.md has the procedure and what a crash loses at each point.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import glob
import hashlib
import json
import os
import shutil
import sqlite3
import subprocess
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sqlalchemy import delete, func, inspect, select, text, update
from sqlalchemy.engine import make_url

from app.core.atomic import atomic_path
from app.core.config import Settings
from app.core.runstore import RunStore
from app.db import migrate
from app.db.models import Base, Job, JobChunk, JobStatus, Run, WorkerHeartbeat
from app.db.session import Database, make_engine

__all__ = [
    "FORMAT",
    "BackupError",
    "BackupResult",
    "RestoreResult",
    "backup",
    "restore",
    "verify_backup",
    "find_pg_tool",
]

#: version of the backup layout (manifest ``format``)
FORMAT = 1
MANIFEST = "manifest.json"
SQLITE_FILE = "database.sqlite"
PG_FILE = "database.dump"
RUNS_DIR = "runs"
_BLOCK = 1024 * 1024
#: ids handed out after a restore start this far above the backup's (see :func:`_skip_ids`)
ID_GAP = 1_000_000
#: tables whose ids leave the service (API answers, feed cursors, delivery ids receivers deduplicate by)
_ID_TABLES = ("runs", "jobs", "condition_flags", "webhook_deliveries", "webhooks", "audit_log")


class BackupError(RuntimeError):
    """A backup cannot be taken, verified or restored (the message says why and what to do)."""


class _RunChanged(Exception):
    """A run file the snapshot refers to vanished during the copy (run deleted or revised)."""


@dataclass
class BackupResult:
    """What :func:`backup` wrote."""

    dest: Path
    database: str
    revision: str | None
    n_runs: int
    n_files: int
    bytes: int
    seconds: float
    attempts: int
    counts: dict[str, int] = field(default_factory=dict)


@dataclass
class RestoreResult:
    """What :func:`restore` did."""

    database: str
    revision_in_backup: str | None
    revision_now: str | None
    n_files: int
    requeued_jobs: list[int]
    previous_run_store: Path | None
    seconds: float


# --- helpers -----------------------------------------------------------------------------------
def _sqlite_path(url: str) -> Path:
    database = make_url(url).database
    if not database or database == ":memory:" or database.startswith("file:"):
        raise BackupError(f"database_url: {url!r} is not a SQLite file")
    return Path(database).expanduser().resolve()


def _kind(url: str) -> str:
    backend = make_url(url).get_backend_name()
    if backend not in ("sqlite", "postgresql"):
        raise BackupError(f"database_url: backups support SQLite and PostgreSQL, got {backend!r}")
    return backend


def find_pg_tool(name: str) -> str:
    """Path of a PostgreSQL client tool (``pg_dump``, ``pg_restore``): PATH, then the newest
    ``/usr/lib/postgresql/*/bin`` (Debian); BackupError when there is none."""
    found = shutil.which(name)
    if found:
        return found
    candidates = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"),
                        key=lambda p: int(Path(p).parts[-3]) if Path(p).parts[-3].isdigit() else 0)
    if candidates:
        return candidates[-1]
    raise BackupError(f"{name} not found: install the PostgreSQL client tools (Debian: postgresql-client) "
                      "of the server's major version or newer")


def _libpq(url: str) -> tuple[str, dict[str, str]]:
    """A libpq connection URI without the password, and the environment carrying it (not on the
    command line, where other users could read it)."""
    parsed = make_url(url)
    env = dict(os.environ)
    if parsed.password:
        env["PGPASSWORD"] = str(parsed.password)
    return parsed.set(drivername="postgresql", password=None).render_as_string(hide_password=False), env


def _sha256_copy(src: Path, dst: Path) -> tuple[int, str]:
    """Copy ``src`` to ``dst`` atomically, hashing on the way: (size, sha256)."""
    h = hashlib.sha256()
    size = 0
    dst.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(dst) as tmp, open(src, "rb") as fin, open(tmp, "wb") as fout:
        while block := fin.read(_BLOCK):
            h.update(block)
            fout.write(block)
            size += len(block)
    return size, h.hexdigest()


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(_BLOCK):
            h.update(block)
    return h.hexdigest()


def _table_counts(conn) -> dict[str, int]:
    names = set(inspect(conn).get_table_names())
    out = {}
    for table in sorted(Base.metadata.tables):
        if table in names:
            out[table] = int(conn.execute(select(func.count()).select_from(Base.metadata.tables[table])).scalar())
    return out


def _revision(conn) -> str | None:
    if "alembic_version" not in inspect(conn).get_table_names():
        return None
    return conn.execute(text("SELECT version_num FROM alembic_version")).scalar()


def _known_revisions() -> tuple[set[str], str]:
    from alembic.script import ScriptDirectory

    script = ScriptDirectory.from_config(migrate.alembic_config("sqlite://"))
    return {r.revision for r in script.walk_revisions()}, script.get_current_head()


def _run_files(conn) -> list[tuple[int, str]]:
    return [(int(i), str(p)) for i, p in conn.execute(select(Run.id, Run.file_path).order_by(Run.id))]


# --- backup ------------------------------------------------------------------------------------
def backup(settings: Settings, dest: Path | str, *, attempts: int = 3) -> BackupResult:
    """Back up the database and the run store of ``settings`` into the new directory ``dest``.

    Parameters
    ----------
    settings : Settings
        The service's settings (database URL, run store).
    dest : Path
        A directory that does not exist yet (or is empty).
    attempts : int
        How many times the backup is taken when a run changes under it (>= 1).

    Raises
    ------
    BackupError
        ``dest`` not empty, the database not reachable or not migrated,
        pg_dump missing or failing, a run file missing although its run
        exists, or the runs kept changing over every attempt.
    """
    if attempts < 1:
        raise ValueError(f"attempts must be >= 1, got {attempts}")
    dest = Path(dest).resolve()
    if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
        raise BackupError(f"DEST: {dest} exists and is not an empty directory")
    kind = _kind(settings.database_url)
    store = RunStore(settings.run_store)
    t0 = time.perf_counter()
    for attempt in range(1, attempts + 1):
        work = dest.with_name(f".{dest.name}.partial-{uuid.uuid4().hex[:8]}")
        work.mkdir(parents=True)
        try:
            manifest = (_backup_sqlite if kind == "sqlite" else _backup_postgresql)(settings, store, work)
        except _RunChanged as exc:
            shutil.rmtree(work, ignore_errors=True)
            if attempt == attempts:
                raise BackupError(f"runs changed during each of {attempts} attempts ({exc}); try again") from None
            continue
        except BaseException:
            shutil.rmtree(work, ignore_errors=True)
            raise
        manifest.update(created_at=dt.datetime.now(dt.UTC).isoformat(), attempts=attempt)
        (work / MANIFEST).write_text(json.dumps(manifest, indent=1, sort_keys=True))
        if dest.exists():
            dest.rmdir()
        os.replace(work, dest)  # the backup appears whole or not at all
        files = manifest["files"]
        return BackupResult(dest, kind, manifest["revision"], len({f["run_id"] for f in files}), len(files),
                            sum(f["size"] for f in files), time.perf_counter() - t0, attempt, manifest["counts"])
    raise AssertionError("unreachable")  # pragma: no cover


def _copy_run_files(store: RunStore, runs: list[tuple[int, str]], work: Path,
                    still_there) -> list[dict[str, Any]]:
    files = []
    for run_id, rel in runs:
        src = store.resolve(rel)
        try:
            size, digest = _sha256_copy(src, work / RUNS_DIR / rel)
        except FileNotFoundError:
            if still_there(run_id, rel):
                raise BackupError(f"run {run_id}: its file {rel} is missing from the run store {store.root} "
                                  "although the run exists; the store is damaged") from None
            raise _RunChanged(f"run {run_id} was deleted or revised") from None
        files.append({"run_id": run_id, "path": rel, "size": size, "sha256": digest})
    return files


def _live_file_is(settings: Settings):
    def check(run_id: int, rel: str) -> bool:
        db = Database(settings.database_url)
        try:
            with db.read() as s:
                return s.scalar(select(Run.file_path).where(Run.id == run_id)) == rel
        finally:
            db.dispose()

    return check


def _backup_sqlite(settings: Settings, store: RunStore, work: Path) -> dict[str, Any]:
    src_path = _sqlite_path(settings.database_url)
    if not src_path.is_file():
        raise BackupError(f"database: {src_path} does not exist")
    target = work / SQLITE_FILE
    src = sqlite3.connect(f"file:{src_path}?mode=ro", uri=True, timeout=60)
    try:
        dst = sqlite3.connect(target)
        try:
            src.backup(dst)  # one step: one read transaction's consistent view (writers go on: WAL)
            dst.execute("PRAGMA journal_mode=DELETE")  # a single self-contained file
        finally:
            dst.close()
    finally:
        src.close()
    _check_sqlite(target)
    engine = make_engine(f"sqlite:///{target}")
    try:
        with engine.connect() as conn:
            revision, counts, runs = _revision(conn), _table_counts(conn), _run_files(conn)
    finally:
        engine.dispose()
    if revision is None:
        raise BackupError("database: not migrated (no Alembic revision): nothing to back up")
    files = _copy_run_files(store, runs, work, _live_file_is(settings))
    return {"format": FORMAT, "database": "sqlite", "database_file": SQLITE_FILE, "revision": revision,
            "counts": counts, "files": files}


def _check_sqlite(path: Path) -> None:
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        result = [r[0] for r in conn.execute("PRAGMA integrity_check")]
    finally:
        conn.close()
    if result != ["ok"]:
        raise BackupError(f"{path.name}: integrity_check failed: {'; '.join(result[:5])}")


def _backup_postgresql(settings: Settings, store: RunStore, work: Path) -> dict[str, Any]:
    pg_dump = find_pg_tool("pg_dump")
    uri, env = _libpq(settings.database_url)
    engine = make_engine(settings.database_url)
    try:
        with engine.connect() as conn:
            conn = conn.execution_options(isolation_level="REPEATABLE READ")
            with conn.begin():
                snapshot = conn.execute(text("SELECT pg_export_snapshot()")).scalar()
                # the dump and the list of runs see the same snapshot
                proc = subprocess.run(
                    [pg_dump, "--format=custom", "--no-owner", "--no-privileges", f"--snapshot={snapshot}",
                     "--file", str(work / PG_FILE), "--dbname", uri],
                    env=env, capture_output=True, text=True, timeout=24 * 3600)
                if proc.returncode != 0:
                    raise BackupError(f"pg_dump failed: {proc.stderr.strip()[-2000:]}")
                revision, counts, runs = _revision(conn), _table_counts(conn), _run_files(conn)
    finally:
        engine.dispose()
    if revision is None:
        raise BackupError("database: not migrated (no Alembic revision): nothing to back up")
    _check_pg_dump(work / PG_FILE)
    files = _copy_run_files(store, runs, work, _live_file_is(settings))
    return {"format": FORMAT, "database": "postgresql", "database_file": PG_FILE, "revision": revision,
            "counts": counts, "files": files}


def _check_pg_dump(path: Path) -> None:
    proc = subprocess.run([find_pg_tool("pg_restore"), "--list", str(path)], capture_output=True, text=True,
                          timeout=3600)
    if proc.returncode != 0 or "TABLE DATA" not in proc.stdout:
        raise BackupError(f"{path.name}: not a readable pg_dump archive: {proc.stderr.strip()[-1000:]}")


# --- verify and restore ------------------------------------------------------------------------
def _read_manifest(src: Path) -> dict[str, Any]:
    try:
        manifest = json.loads((src / MANIFEST).read_text())
    except FileNotFoundError:
        raise BackupError(f"SRC: {src} has no {MANIFEST}: not a trackvkf backup") from None
    except ValueError as exc:
        raise BackupError(f"SRC: {MANIFEST} is not valid JSON ({exc})") from None
    if manifest.get("format") != FORMAT:
        raise BackupError(f"SRC: backup format {manifest.get('format')!r}, this version reads {FORMAT}")
    return manifest


def verify_backup(src: Path | str) -> dict[str, Any]:
    """Check a backup without restoring it: the manifest, every run file's size and sha256, the
    database snapshot (integrity_check / pg_restore --list), and a known Alembic revision.

    Returns
    -------
    dict
        The manifest.

    Raises
    ------
    BackupError
        Naming the first problem found.
    """
    src = Path(src).resolve()
    manifest = _read_manifest(src)
    for f in manifest["files"]:
        path = (src / RUNS_DIR / f["path"]).resolve()
        if src / RUNS_DIR not in path.parents:
            raise BackupError(f"SRC: file {f['path']!r} leaves the backup")
        if not path.is_file():
            raise BackupError(f"SRC: run file {f['path']} is missing")
        if path.stat().st_size != f["size"] or _sha256(path) != f["sha256"]:
            raise BackupError(f"SRC: run file {f['path']} does not match its checksum")
    db_file = src / manifest["database_file"]
    if not db_file.is_file():
        raise BackupError(f"SRC: {manifest['database_file']} is missing")
    if manifest["database"] == "sqlite":
        _check_sqlite(db_file)
    else:
        _check_pg_dump(db_file)
    known, _ = _known_revisions()
    if manifest["revision"] not in known:
        raise BackupError(f"SRC: database revision {manifest['revision']!r} is unknown to this version "
                          "(a backup of a newer trackvkf): restore it with that version")
    return manifest


def _holds_data(settings: Settings, kind: str) -> list[str]:
    """What the target already holds (empty: nothing to overwrite)."""
    held = []
    store = RunStore(settings.run_store)
    if store.run_ids_on_disk():
        held.append(f"run store {store.root} holds runs")
    if kind == "sqlite" and not _sqlite_path(settings.database_url).is_file():
        return held
    try:
        engine = make_engine(settings.database_url)
        try:
            with engine.connect() as conn:
                if "runs" in inspect(conn).get_table_names() and conn.execute(
                        select(func.count()).select_from(Run)).scalar():
                    held.append(f"database {engine.url.render_as_string()} holds runs")
        finally:
            engine.dispose()
    except Exception as exc:  # noqa: BLE001 - an unreachable target is reported by the restore itself
        held.append(f"database cannot be inspected ({type(exc).__name__})")
    return held


def restore(settings: Settings, src: Path | str, *, force: bool = False) -> RestoreResult:
    """Restore the backup ``src`` into the database and run store of ``settings`` (service stopped).

    Parameters
    ----------
    settings : Settings
        Where to restore: ``database_url`` (of the backup's kind) and ``run_store``.
    src : Path
        A directory written by :func:`backup`.
    force : bool
        Overwrite a target that holds data (its run store is kept aside).

    Raises
    ------
    BackupError
        The backup fails verification, is of the other database kind, the
        target holds data without ``force``, or a restore step fails.
    """
    t0 = time.perf_counter()
    src = Path(src).resolve()
    manifest = verify_backup(src)
    kind = _kind(settings.database_url)
    if manifest["database"] != kind:
        raise BackupError(f"SRC: a {manifest['database']} backup cannot be restored into {kind} "
                          f"({settings.database_url})")
    held = _holds_data(settings, kind)
    if held and not force:
        raise BackupError("the target is not empty (" + "; ".join(held) + "): stop the service and restore with "
                          "--force to replace it (the current run store is kept aside)")
    store_root = Path(settings.run_store).resolve()
    staging = store_root.with_name(f".{store_root.name}.restore-{uuid.uuid4().hex[:8]}")
    try:
        for f in manifest["files"]:  # run files first: nothing of the target is touched yet
            size, digest = _sha256_copy(src / RUNS_DIR / f["path"], staging / f["path"])
            if (size, digest) != (f["size"], f["sha256"]):
                raise BackupError(f"run file {f['path']} changed while it was copied")
        if kind == "sqlite":
            _restore_sqlite(settings, src / manifest["database_file"])
        else:
            _restore_postgresql(settings, src / manifest["database_file"])
        previous = None
        if store_root.exists() and not any(p.is_file() for p in store_root.rglob("*")):
            shutil.rmtree(store_root)  # empty (a fresh service's): nothing to keep
        if store_root.exists():
            previous = store_root.with_name(f"{store_root.name}.before-restore-"
                                            f"{dt.datetime.now(dt.UTC).strftime('%Y%m%dT%H%M%SZ')}")
            os.replace(store_root, previous)
        staging.mkdir(parents=True, exist_ok=True)
        os.replace(staging, store_root)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    _, head = _known_revisions()
    if manifest["revision"] != head:
        migrate.upgrade(settings.database_url)
    revision_now = migrate.current_revision(settings.database_url)
    if revision_now != head:
        raise BackupError(f"restored database at {revision_now!r}, not at the head {head!r}")
    requeued = _after_restore(settings, manifest)
    return RestoreResult(kind, manifest["revision"], revision_now, len(manifest["files"]), requeued, previous,
                         time.perf_counter() - t0)


def _restore_sqlite(settings: Settings, snapshot: Path) -> None:
    target = _sqlite_path(settings.database_url)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.restore-{uuid.uuid4().hex[:8]}")
    try:
        shutil.copyfile(snapshot, tmp)
        _check_sqlite(tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        for suffix in ("-wal", "-shm", "-journal"):  # of the database being replaced
            with contextlib.suppress(FileNotFoundError):
                os.unlink(f"{target}{suffix}")
        os.replace(tmp, target)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
    _check_sqlite(target)


def _restore_postgresql(settings: Settings, dump: Path) -> None:
    uri, env = _libpq(settings.database_url)
    proc = subprocess.run(
        [find_pg_tool("pg_restore"), "--clean", "--if-exists", "--no-owner", "--no-privileges",
         "--single-transaction", "--exit-on-error", "--dbname", uri, str(dump)],
        env=env, capture_output=True, text=True, timeout=24 * 3600)
    if proc.returncode != 0:
        raise BackupError(f"pg_restore failed: {proc.stderr.strip()[-2000:]}")


@contextlib.contextmanager
def _database(url: str) -> Iterator[Database]:
    db = Database(url)
    try:
        yield db
    finally:
        db.dispose()


def _after_restore(settings: Settings, manifest: dict[str, Any]) -> list[int]:
    """Check the restored rows against the manifest; requeue the jobs that were running; forget
    the heartbeats of the workers of the backed-up service."""
    with _database(settings.database_url) as db:
        with db.read() as s:
            counts = _table_counts(s.connection())
        expected = manifest["counts"]
        wrong = {t: (counts.get(t), n) for t, n in expected.items() if counts.get(t) != n}
        if wrong:
            raise BackupError(f"restored row counts differ from the backup's (table: now, backup): {wrong}")
        with db.write() as s:
            running = list(s.scalars(select(Job.id).where(Job.status == JobStatus.RUNNING).order_by(Job.id)))
            if running:  # their chunk files were not backed up: they start again from the first chunk
                s.execute(delete(JobChunk).where(JobChunk.job_id.in_(running)))
                s.execute(update(Job).where(Job.id.in_(running)).values(
                    status=JobStatus.QUEUED, worker_id=None, heartbeat_at=None, progress=0.0, n_chunks=None))
            s.execute(delete(WorkerHeartbeat))
            _skip_ids(s)
    return running


def _skip_ids(session) -> None:
    """Move the id sequences of :data:`_ID_TABLES` :data:`ID_GAP` ahead.

    The ids the lost period (after the backup) handed out were seen outside:
    run and job ids in other systems, the flag feed's ``since`` cursors,
    delivery ids that receivers deduplicate by. Were they handed out again for
    other rows, a receiver would drop a new alert as a duplicate and a feed
    reader would skip new flags. A gap keeps new ids above every id the lost
    period can have used (fewer than a million rows per table).
    """
    if session.get_bind().dialect.name == "sqlite":
        for table in _ID_TABLES:
            found = session.execute(text("SELECT seq FROM sqlite_sequence WHERE name = :t"), {"t": table}).first()
            if found is None:
                session.execute(text("INSERT INTO sqlite_sequence (name, seq) VALUES (:t, :g)"),
                                {"t": table, "g": ID_GAP})
            else:
                session.execute(text("UPDATE sqlite_sequence SET seq = seq + :g WHERE name = :t"),
                                {"t": table, "g": ID_GAP})
        return
    for table in _ID_TABLES:
        seq = session.execute(text("SELECT pg_get_serial_sequence(:t, 'id')"), {"t": table}).scalar()
        if seq is None:
            continue
        session.execute(text(f"SELECT setval('{seq}', (SELECT CASE WHEN is_called THEN last_value ELSE "
                             f"last_value - 1 END FROM {seq}) + :g)"), {"g": ID_GAP})
