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

``trackvkf restore SRC`` verifies the backup, read-only, before it touches anything
(:mod:`app.operations.restore_checks`: no symbolic link under it, the manifest's shape and
relative paths, the sha256 of every run file, the snapshot's integrity, Alembic revision, row
counts and run files against the manifest, a revision this version knows). Then it copies the
run files into a staging directory (hashed again), keeps the target's database aside (SQLite:
renamed with its WAL to ``<db>.before-restore-<time>``; PostgreSQL: a ``pg_dump`` of it to
``<run_store>.before-restore-<time>.database.dump``), restores the database (SQLite: the
snapshot replaces the database file; PostgreSQL: ``pg_restore --clean``), swaps the run store
in (an existing one kept aside as ``<run_store>.before-restore-<time>``), checks the restored
database's row counts against the manifest and upgrades it to the Alembic head when the backup
is older. A failure in these steps puts the old database and run store back. Last, it requeues
the jobs that were running when the backup was taken. The service must be stopped during a
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

from sqlalchemy import create_engine, delete, func, inspect, select, text, update
from sqlalchemy.engine import make_url
from sqlalchemy.pool import NullPool

from app.core.atomic import atomic_path
from app.core.config import CoreSettings
from app.core.runstore import RunStore
from app.db import migrate
from app.db.models import Base, Job, JobChunk, JobStatus, Run, WorkerHeartbeat
from app.db.session import Database, make_engine
from app.operations import restore_checks as checks

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
SQLITE_FILE = checks.DATABASE_FILES["sqlite"]
PG_FILE = checks.DATABASE_FILES["postgresql"]
RUNS_DIR = checks.RUNS_DIR
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
    previous_database: Path | None = None


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
    """The runs' files; a run without one (written by ``simulate-fleet``: results only) has none to copy."""
    return [(int(i), str(p)) for i, p in conn.execute(select(Run.id, Run.file_path).order_by(Run.id)) if p]


# --- backup ------------------------------------------------------------------------------------
def backup(settings: CoreSettings, dest: Path | str, *, attempts: int = 3) -> BackupResult:
    """Back up the database and the run store of ``settings`` into the new directory ``dest``.

    Parameters
    ----------
    settings : CoreSettings
        The service's core settings (database URL, run store; the service's :class:`~app.settings.Settings`
        are core settings too).
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


def _live_file_is(settings: CoreSettings):
    def check(run_id: int, rel: str) -> bool:
        db = Database(settings.database_url)
        try:
            with db.read() as s:
                return s.scalar(select(Run.file_path).where(Run.id == run_id)) == rel
        finally:
            db.dispose()

    return check


def _backup_sqlite(settings: CoreSettings, store: RunStore, work: Path) -> dict[str, Any]:
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
    engine = _read_only_engine(target)  # make_engine would turn the snapshot to WAL mode
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


def _read_only_engine(path: Path):
    return create_engine("sqlite://", creator=lambda: sqlite3.connect(checks.read_only_uri(path), uri=True),
                         poolclass=NullPool)


def _check_sqlite(path: Path) -> None:
    try:
        conn = sqlite3.connect(checks.read_only_uri(path), uri=True)
        try:
            result = [r[0] for r in conn.execute("PRAGMA integrity_check")]
        finally:
            conn.close()
    except sqlite3.Error as exc:
        raise BackupError(f"{path.name}: not a readable SQLite database: {exc}") from None
    if result != ["ok"]:
        raise BackupError(f"{path.name}: integrity_check failed: {'; '.join(result[:5])}")


def _backup_postgresql(settings: CoreSettings, store: RunStore, work: Path) -> dict[str, Any]:
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
        raw = (src / MANIFEST).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise BackupError(f"SRC: {src} has no {MANIFEST}: not a trackvkf backup") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BackupError(f"SRC: {MANIFEST} cannot be read ({exc})") from None
    try:
        manifest = json.loads(raw)
    except (ValueError, RecursionError) as exc:
        raise BackupError(f"SRC: {MANIFEST} is not valid JSON ({exc})") from None
    return checks.check_manifest(manifest, FORMAT)


def verify_backup(src: Path | str) -> dict[str, Any]:
    """Check a backup without restoring it, read-only (:mod:`app.operations.restore_checks`): no
    symbolic link anywhere under it, the manifest's shape and paths (relative, no ``..``), every
    run file's size and sha256, the database file of its kind in it, the snapshot (integrity,
    then its Alembic revision, row counts per table and run files against the manifest's), and a
    revision this version knows.

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
    try:
        checks.check_tree(src)
        manifest = _read_manifest(src)
        checks.check_run_files(src, manifest["files"])
        db_file = checks.database_file(src, manifest)
        if manifest["database"] == "sqlite":
            snapshot = checks.read_sqlite(db_file)
        else:
            snapshot = checks.read_pg_dump(db_file, find_pg_tool("pg_restore"))
        known, _ = _known_revisions()
        if manifest["revision"] not in known:
            raise BackupError(f"SRC: database revision {manifest['revision']!r} is unknown to this version "
                              "(a backup of a newer trackvkf): restore it with that version")
        checks.compare_snapshot(snapshot, manifest, set(Base.metadata.tables))
    except checks.BackupCheckError as exc:
        raise BackupError(str(exc)) from None
    except FileNotFoundError as exc:
        raise BackupError(f"SRC: {exc.filename or src} does not exist") from None
    except OSError as exc:
        raise BackupError(f"SRC: cannot be read ({exc})") from None
    return manifest


def _holds_data(settings: CoreSettings, kind: str) -> list[str]:
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


@dataclass
class _Aside:
    """The target's old database and run store, kept until the restored ones are verified."""

    stamp: str
    database: Path | None = None
    run_store: Path | None = None
    wal: list[tuple[Path, Path]] = field(default_factory=list)
    swapped: bool = False


def restore(settings: CoreSettings, src: Path | str, *, force: bool = False) -> RestoreResult:
    """Restore the backup ``src`` into the database and run store of ``settings`` (service stopped).

    Everything is verified before the target is touched (:func:`verify_backup`); the target's old
    database and run store are then kept aside (SQLite: the database file renamed; PostgreSQL: a
    ``pg_dump`` of it; the run store renamed) and put back if the restored database fails its
    checks (the revision after the upgrade, the row counts against the manifest).

    Parameters
    ----------
    settings : CoreSettings
        Where to restore: ``database_url`` (of the backup's kind) and ``run_store``.
    src : Path
        A directory written by :func:`backup`.
    force : bool
        Overwrite a target that holds data (its database and run store are kept aside).

    Raises
    ------
    BackupError
        The backup fails verification, is of the other database kind, the
        target holds data without ``force``, or a restore step fails (the
        target then as it was).
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
                          "--force to replace it (its database and run store are kept aside)")
    store_root = Path(settings.run_store).resolve()
    staging = store_root.with_name(f".{store_root.name}.restore-{uuid.uuid4().hex[:8]}")
    aside = _Aside(dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ"))
    try:
        for f in manifest["files"]:  # run files first: nothing of the target is touched yet
            size, digest = _sha256_copy(src / RUNS_DIR / f["path"], staging / f["path"])
            if (size, digest) != (f["size"], f["sha256"]):
                raise BackupError(f"run file {f['path']} changed while it was copied")
        staging.mkdir(parents=True, exist_ok=True)
        try:
            if kind == "sqlite":
                _sqlite_aside(settings, aside)
                _restore_sqlite(settings, src / checks.DATABASE_FILES[kind])
            else:
                _postgresql_aside(settings, store_root, aside)
                _restore_postgresql(settings, src / checks.DATABASE_FILES[kind])
            _swap_run_store(store_root, staging, aside)
            revision_now = _upgrade_and_check(settings, manifest)
        except BaseException as exc:
            _put_back(settings, kind, store_root, aside)
            if isinstance(exc, BackupError):
                raise BackupError(f"{exc}; the target is as it was before the restore") from None
            raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    requeued = _after_restore(settings)
    return RestoreResult(kind, manifest["revision"], revision_now, len(manifest["files"]), requeued,
                         aside.run_store, time.perf_counter() - t0, aside.database)


def _sqlite_aside(settings: CoreSettings, aside: _Aside) -> None:
    """Rename the target's SQLite database (with its WAL) aside; nothing when there is none."""
    target = _sqlite_path(settings.database_url)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(f"{target}-shm")  # rebuilt from the WAL by whoever opens the database next
    if not target.exists():
        return
    kept = target.with_name(f"{target.name}.before-restore-{aside.stamp}")
    os.replace(target, kept)
    aside.database = kept
    for suffix in ("-wal", "-journal"):  # the database's uncheckpointed pages stay with it
        if Path(f"{target}{suffix}").exists():
            os.replace(f"{target}{suffix}", f"{kept}{suffix}")
            aside.wal.append((Path(f"{target}{suffix}"), Path(f"{kept}{suffix}")))


def _postgresql_aside(settings: CoreSettings, store_root: Path, aside: _Aside) -> None:
    """``pg_dump`` of the target database beside the run store, when it holds a trackvkf schema."""
    engine = make_engine(settings.database_url)
    try:
        with engine.connect() as conn:
            if "alembic_version" not in inspect(conn).get_table_names():
                return
    finally:
        engine.dispose()
    kept = store_root.with_name(f"{store_root.name}.before-restore-{aside.stamp}.database.dump")
    uri, env = _libpq(settings.database_url)
    with atomic_path(kept) as tmp:
        proc = subprocess.run([find_pg_tool("pg_dump"), "--format=custom", "--no-owner", "--no-privileges",
                               "--file", str(tmp), "--dbname", uri],
                              env=env, capture_output=True, text=True, timeout=24 * 3600)
        if proc.returncode != 0:
            raise BackupError(f"pg_dump of the target (to keep it aside) failed: {proc.stderr.strip()[-2000:]}")
    aside.database = kept


def _swap_run_store(store_root: Path, staging: Path, aside: _Aside) -> None:
    if store_root.exists() and not any(p.is_file() for p in store_root.rglob("*")):
        shutil.rmtree(store_root)  # empty (a fresh service's): nothing to keep
    if store_root.exists():
        kept = store_root.with_name(f"{store_root.name}.before-restore-{aside.stamp}")
        os.replace(store_root, kept)
        aside.run_store = kept
    os.replace(staging, store_root)
    aside.swapped = True


def _upgrade_and_check(settings: CoreSettings, manifest: dict[str, Any]) -> str | None:
    """Upgrade the restored database to the head when the backup is older; check its revision and
    (at the backup's revision) its row counts against the manifest."""
    _, head = _known_revisions()
    with _database(settings.database_url) as db:
        with db.read() as s:
            counts = _table_counts(s.connection())
    wrong = {t: (counts.get(t), n) for t, n in manifest["counts"].items() if counts.get(t) != n}
    if wrong:
        raise BackupError(f"restored row counts differ from the backup's (table: now, backup): {wrong}")
    if manifest["revision"] != head:
        migrate.upgrade(settings.database_url)
    revision_now = migrate.current_revision(settings.database_url)
    if revision_now != head:
        raise BackupError(f"restored database at {revision_now!r}, not at the head {head!r}")
    return revision_now


def _put_back(settings: CoreSettings, kind: str, store_root: Path, aside: _Aside) -> None:
    """Undo a restore that failed after it touched the target: the old database and run store back."""
    if aside.swapped:
        failed = store_root.with_name(f".{store_root.name}.failed-restore-{aside.stamp}")
        os.replace(store_root, failed)
        shutil.rmtree(failed, ignore_errors=True)
        if aside.run_store is not None:
            os.replace(aside.run_store, store_root)
        aside.run_store, aside.swapped = None, False
    if kind == "sqlite":
        target = _sqlite_path(settings.database_url)
        for suffix in ("-wal", "-shm", "-journal"):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(f"{target}{suffix}")
        if aside.database is not None:
            os.replace(aside.database, target)
            for live, kept in aside.wal:
                os.replace(kept, live)
        else:
            with contextlib.suppress(FileNotFoundError):
                target.unlink()
    elif aside.database is not None:
        _restore_postgresql(settings, aside.database)
        aside.database.unlink()
    aside.database = None


def _restore_sqlite(settings: CoreSettings, snapshot: Path) -> None:
    target = _sqlite_path(settings.database_url)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.restore-{uuid.uuid4().hex[:8]}")
    try:
        shutil.copyfile(snapshot, tmp)
        _check_sqlite(tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
    _check_sqlite(target)


def _restore_postgresql(settings: CoreSettings, dump: Path) -> None:
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


def _after_restore(settings: CoreSettings) -> list[int]:
    """Requeue the jobs that were running; forget the heartbeats of the workers of the backed-up
    service; move the id sequences ahead."""
    with _database(settings.database_url) as db, db.write() as s:
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
