"""What a restore checks before it touches anything: the backup directory, its manifest and its
database snapshot, all read-only.

A backup comes from outside the service (copied off the host and back, possibly tampered
with), so nothing in it is trusted until checked:

* the **manifest** has the shape :func:`app.operations.backup.backup` writes (every key, of its
  type; a run file path relative, without ``..``, ``.`` or empty parts, below ``runs/``);
* **no symbolic link** anywhere under the backup (``lstat`` of every entry, the directory
  itself included): a link would make a check read one file and the copy write another;
* the **database file** is the plain file the backup's kind names (``database.sqlite`` or
  ``database.dump``) directly in the backup;
* every run file a regular file of the manifest's size and sha256;
* the **snapshot**, opened read-only, holds the manifest's Alembic revision and exactly its row
  count per table (SQLite: the file opened ``mode=ro&immutable=1``, ``PRAGMA integrity_check``
  first; PostgreSQL: the archive's table of contents and its data streamed through
  ``pg_restore --data-only --file=-`` and counted), and its runs refer to exactly the
  manifest's run files.

Every problem raises :class:`BackupCheckError` naming it; the caller turns it into the one
``error:`` line of the command.
"""

from __future__ import annotations

import hashlib
import os
import re
import sqlite3
import stat
import subprocess
from pathlib import Path, PurePosixPath
from typing import Any
from urllib.parse import quote

__all__ = ["BackupCheckError", "Snapshot", "check_manifest", "check_tree", "check_run_files", "read_sqlite",
           "read_pg_dump", "compare_snapshot", "read_only_uri", "DATABASE_FILES", "RUNS_DIR"]

#: The database file of a backup, by kind (always directly in the backup directory).
DATABASE_FILES = {"sqlite": "database.sqlite", "postgresql": "database.dump"}
RUNS_DIR = "runs"
_BLOCK = 1024 * 1024
_TABLE = re.compile(r"^[a-z_][a-z0-9_]{0,62}$")
_SHA256 = re.compile(r"^[0-9a-f]{64}$")
#: a partition attached to its table in a dump's schema (its rows count as the table's)
_ATTACH = re.compile(r'^ALTER TABLE (?:ONLY )?(?:"?[\w$]+"?\.)?"?([\w$]+)"? ATTACH PARTITION '
                     r'(?:"?[\w$]+"?\.)?"?([\w$]+)"? ')
_COPY = re.compile(r'^COPY (?:"?[\w$]+"?\.)?"?([\w$]+)"? \(.*\) FROM stdin;$')


class BackupCheckError(ValueError):
    """The backup fails a check (the message names what and where)."""


class Snapshot(dict):
    """What a database snapshot holds: ``revision`` (str or None), ``counts`` (table → rows) and
    ``run_files`` (the runs' file paths, empty ones left out)."""


def _need(cond: bool, message: str) -> None:
    if not cond:
        raise BackupCheckError(f"SRC: manifest.json: {message}")


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def relative_run_path(value: Any, where: str) -> PurePosixPath:
    """A manifest's run file path, refused unless relative with plain parts (no ``..``, ``.``, empty,
    backslash or NUL)."""
    _need(isinstance(value, str) and 0 < len(value) <= 1024, f"{where}: must be a non-empty path")
    _need("\\" not in value and "\x00" not in value, f"{where}: {value!r} holds a backslash or NUL")
    path = PurePosixPath(value)
    _need(not path.is_absolute(), f"{where}: {value!r} is absolute (only paths relative to runs/ are read)")
    parts = value.split("/")
    _need(all(p not in ("", ".", "..") for p in parts), f"{where}: {value!r} has a '..', '.' or empty part")
    return path


def check_manifest(manifest: Any, format_: int) -> dict[str, Any]:
    """The manifest, checked to have every key of the shape :func:`~app.operations.backup.backup`
    writes.

    Raises
    ------
    BackupCheckError
        Naming the key.
    """
    _need(isinstance(manifest, dict), "must be a JSON object")
    _need(manifest.get("format") == format_, f"backup format {manifest.get('format')!r}, this version reads {format_}")
    kind = manifest.get("database")
    _need(kind in DATABASE_FILES, f"database: must be one of {', '.join(DATABASE_FILES)}, got {kind!r}")
    _need(manifest.get("database_file") == DATABASE_FILES[kind],
          f"database_file: must be {DATABASE_FILES[kind]!r} (the file in the backup), got "
          f"{manifest.get('database_file')!r}")
    _need(isinstance(manifest.get("revision"), str) and bool(manifest["revision"]), "revision: missing")
    counts = manifest.get("counts")
    _need(isinstance(counts, dict) and "runs" in counts, "counts: missing (rows per table)")
    for table, n in counts.items():
        _need(isinstance(table, str) and bool(_TABLE.match(table)), f"counts: {table!r} is not a table name")
        _need(_is_int(n) and n >= 0, f"counts.{table}: must be a row count, got {n!r}")
    files = manifest.get("files")
    _need(isinstance(files, list), "files: missing (the run files)")
    seen: set[str] = set()
    for i, f in enumerate(files):
        where = f"files[{i}]"
        _need(isinstance(f, dict), f"{where}: must be an object")
        _need(_is_int(f.get("run_id")) and f["run_id"] >= 1, f"{where}.run_id: must be a run id")
        relative_run_path(f.get("path"), f"{where}.path")
        _need(f["path"] not in seen, f"{where}.path: {f['path']!r} is listed twice")
        seen.add(f["path"])
        _need(_is_int(f.get("size")) and f["size"] >= 0, f"{where}.size: must be a size in bytes")
        _need(isinstance(f.get("sha256"), str) and bool(_SHA256.match(f["sha256"])),
              f"{where}.sha256: must be 64 hex digits")
    return manifest


def check_tree(src: Path) -> None:
    """Refuse a backup with a symbolic link (or anything but directories and regular files) anywhere
    under it, ``src`` itself included (``lstat``, links never followed)."""
    mode = os.lstat(src).st_mode
    if stat.S_ISLNK(mode) or not stat.S_ISDIR(mode):
        raise BackupCheckError(f"SRC: {src} is {'a symbolic link' if stat.S_ISLNK(mode) else 'not a directory'}"
                               " (give the backup directory itself)")
    for top, dirs, files in os.walk(src, followlinks=False):
        for name in (*dirs, *files):
            path = Path(top) / name
            mode = os.lstat(path).st_mode
            if stat.S_ISLNK(mode):
                raise BackupCheckError(f"SRC: {path.relative_to(src)} is a symbolic link (a backup holds none)")
            if not (stat.S_ISDIR(mode) or stat.S_ISREG(mode)):
                raise BackupCheckError(f"SRC: {path.relative_to(src)} is not a regular file or directory")


def _regular(path: Path, what: str) -> os.stat_result:
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise BackupCheckError(f"SRC: {what} is missing") from None
    if not stat.S_ISREG(st.st_mode):
        raise BackupCheckError(f"SRC: {what} is not a regular file")
    return st


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(_BLOCK):
            h.update(block)
    return h.hexdigest()


def check_run_files(src: Path, files: list[dict[str, Any]]) -> None:
    """Every run file of the manifest a regular file under ``src/runs`` of its size and sha256
    (run after :func:`check_tree`: no link can redirect a path)."""
    for f in files:
        path = src / RUNS_DIR / f["path"]
        st = _regular(path, f"run file {f['path']}")
        if st.st_size != f["size"] or _sha256(path) != f["sha256"]:
            raise BackupCheckError(f"SRC: run file {f['path']} does not match its checksum")


def database_file(src: Path, manifest: dict[str, Any]) -> Path:
    """The backup's database file (a regular file directly in ``src``)."""
    path = src / DATABASE_FILES[manifest["database"]]
    _regular(path, manifest["database_file"])
    return path


def read_only_uri(path: Path) -> str:
    """A SQLite URI opening ``path`` read-only and immutable (nothing written beside it, no -wal or -shm)."""
    return f"file:{quote(str(path))}?mode=ro&immutable=1"


def read_sqlite(path: Path) -> Snapshot:
    """A SQLite snapshot opened read-only (``immutable``: nothing written beside it), its integrity
    checked, its revision, row counts and run files read.

    Raises
    ------
    BackupCheckError
        Not a database, damaged (integrity_check), or unreadable.
    """
    name = path.name
    try:
        conn = sqlite3.connect(read_only_uri(path), uri=True)
    except sqlite3.Error as exc:
        raise BackupCheckError(f"SRC: {name} cannot be opened: {exc}") from None
    try:
        result = [r[0] for r in conn.execute("PRAGMA integrity_check")]
        if result != ["ok"]:
            raise BackupCheckError(f"SRC: {name}: integrity_check failed: {'; '.join(map(str, result[:5]))}")
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        revision = None
        if "alembic_version" in tables:
            row = conn.execute("SELECT version_num FROM alembic_version").fetchone()
            revision = row[0] if row else None
        counts = {t: int(conn.execute(f'SELECT count(*) FROM "{t}"').fetchone()[0])
                  for t in sorted(tables) if _TABLE.match(t) and not t.startswith("sqlite_")}
        run_files = set()
        if "runs" in tables:
            run_files = {r[0] for r in conn.execute("SELECT file_path FROM runs") if r[0]}
    except sqlite3.Error as exc:
        raise BackupCheckError(f"SRC: {name} is not a readable SQLite database: {exc}") from None
    finally:
        conn.close()
    return Snapshot(revision=revision, counts=counts, run_files=run_files)


def read_pg_dump(path: Path, pg_restore: str, *, timeout_s: float = 24 * 3600) -> Snapshot:
    """A ``pg_dump --format=custom`` archive read without restoring it: its table of contents
    checked (``pg_restore --list``), its data streamed (``pg_restore --data-only --file=-``) and
    counted row by row per table (COPY text format: one line a row; a partition's rows
    counted as its table's, ``ATTACH PARTITION`` of the schema), the revision and the runs' file paths read on the way.

    Raises
    ------
    BackupCheckError
        Not a readable archive.
    """
    name = path.name
    listed = subprocess.run([pg_restore, "--list", str(path)], capture_output=True, text=True, timeout=3600)
    if listed.returncode != 0 or "TABLE DATA" not in listed.stdout:
        raise BackupCheckError(f"SRC: {name}: not a readable pg_dump archive: {listed.stderr.strip()[-1000:]}")
    schema = subprocess.run([pg_restore, "--schema-only", "--file=-", str(path)], capture_output=True, text=True,
                            timeout=3600)
    if schema.returncode != 0:
        raise BackupCheckError(f"SRC: {name}: its schema cannot be read: {schema.stderr.strip()[-1000:]}")
    parent = {m.group(2): m.group(1) for m in map(_ATTACH.match, schema.stdout.splitlines()) if m}
    counts: dict[str, int] = {}
    revision = None
    run_files: set[str] = set()
    file_col = None
    table = None
    proc = subprocess.Popen([pg_restore, "--data-only", "--file=-", str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, encoding="utf-8", errors="replace")
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            line = line.rstrip("\n")
            if table is None:
                m = _COPY.match(line)
                if m:
                    table = parent.get(m.group(1), m.group(1))
                    counts.setdefault(table, 0)
                    cols = [c.strip().strip('"') for c in line[line.index("(") + 1:line.rindex(")")].split(",")]
                    file_col = cols.index("file_path") if table == "runs" and "file_path" in cols else None
                continue
            if line == "\\.":
                table = None
                continue
            counts[table] += 1
            if table == "alembic_version":
                revision = line.split("\t")[0]
            elif file_col is not None:
                value = line.split("\t")[file_col]
                if value and value != "\\N":
                    run_files.add(value)
        _, err = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if proc.returncode != 0 or table is not None:
        raise BackupCheckError(f"SRC: {name}: its data cannot be read: {err.strip()[-1000:] or 'cut short'}")
    return Snapshot(revision=revision, counts=counts, run_files=run_files)


def compare_snapshot(snapshot: Snapshot, manifest: dict[str, Any], known_tables: set[str]) -> None:
    """The snapshot holds what the manifest says: its revision, every table's row count (each of
    its tables this version knows, ``known_tables``, counted in the manifest), the run files (every
    run with a file has it in the manifest, and nothing more).

    Raises
    ------
    BackupCheckError
        Naming the first difference.
    """
    name = manifest["database_file"]
    if snapshot["revision"] != manifest["revision"]:
        raise BackupCheckError(f"SRC: {name} is at revision {snapshot['revision']!r}, the manifest says "
                               f"{manifest['revision']!r}")
    uncounted = sorted((set(snapshot["counts"]) & known_tables) - set(manifest["counts"]))
    if uncounted:
        raise BackupCheckError(f"SRC: manifest.json: counts: {name}'s tables {uncounted[:5]} are not counted")
    wrong = {t: (snapshot["counts"].get(t), n) for t, n in manifest["counts"].items()
             if snapshot["counts"].get(t) != n}
    if wrong:
        raise BackupCheckError(f"SRC: {name}'s row counts differ from the manifest's (table: snapshot, "
                               f"manifest): {dict(sorted(wrong.items())[:5])}")
    listed = {f["path"] for f in manifest["files"]}
    if snapshot["run_files"] != listed:
        missing = sorted(snapshot["run_files"] - listed)[:3]
        extra = sorted(listed - snapshot["run_files"])[:3]
        raise BackupCheckError(f"SRC: the manifest's run files differ from {name}'s runs (not listed: {missing}; "
                               f"no such run: {extra})")
