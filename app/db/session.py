"""Engine and sessions for SQLite (embedded) and PostgreSQL.

:class:`Database` hands out two kinds of session:

``read()``
    for queries; on SQLite a deferred transaction (readers never block in WAL mode).
``write()``
    for changes; commits at the end of the block, rolls back on an exception.
    On SQLite it starts with ``BEGIN IMMEDIATE``, taking the write lock up
    front, so two processes (API and worker) never dead-lock upgrading a read
    lock and a busy writer is waited for (``busy_timeout``) instead of failing.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

from sqlalchemy import Engine, create_engine, event
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

__all__ = ["Database", "make_engine"]

_SQLITE_BUSY_TIMEOUT_MS = 60_000


def make_engine(url: str, *, sqlite_foreign_keys: bool = True, lock_wait_s: float | None = None,
                **kwargs) -> Engine:
    """Create an engine for ``url`` with the service's connection settings.

    Parameters
    ----------
    url : str
        SQLAlchemy database URL. For a file SQLite URL the parent directory is
        created; connections get WAL journaling, foreign keys on and a busy
        timeout (``lock_wait_s``).
    sqlite_foreign_keys : bool
        Enforce foreign keys on SQLite connections (default). Migrations turn
        it off: SQLite batch operations recreate tables.
    lock_wait_s : float, optional
        SQLite: how long a connection waits for the write lock, retrying, before
        it fails with ``database is locked`` (default 60 s).
    **kwargs
        Passed to :func:`sqlalchemy.create_engine`.
    """
    parsed = make_url(url)
    if parsed.get_backend_name() != "sqlite":
        kwargs.setdefault("pool_pre_ping", True)
        return create_engine(url, **kwargs)

    database = parsed.database
    if database and database != ":memory:" and not database.startswith("file:"):
        Path(database).expanduser().parent.mkdir(parents=True, exist_ok=True)
    connect_args = kwargs.pop("connect_args", {})
    connect_args.setdefault("check_same_thread", False)
    busy_ms = _SQLITE_BUSY_TIMEOUT_MS if lock_wait_s is None else max(1, round(lock_wait_s * 1000))
    connect_args.setdefault("timeout", busy_ms / 1000)
    engine = create_engine(url, connect_args=connect_args, **kwargs)

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection, connection_record) -> None:  # noqa: ARG001
        # Let SQLAlchemy, not the sqlite3 module, emit BEGIN (see _on_begin).
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        cursor.execute(f"PRAGMA foreign_keys={'ON' if sqlite_foreign_keys else 'OFF'}")
        cursor.execute(f"PRAGMA busy_timeout={busy_ms}")
        if database and database != ":memory:":
            cursor.execute("PRAGMA journal_mode=WAL")
            cursor.execute("PRAGMA synchronous=NORMAL")
        cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn) -> None:
        immediate = conn.get_execution_options().get("sqlite_immediate", False)
        conn.exec_driver_sql("BEGIN IMMEDIATE" if immediate else "BEGIN")

    return engine


class Database:
    """An engine plus read and write session factories.

    Parameters
    ----------
    url : str
        SQLAlchemy database URL.
    """

    def __init__(self, url: str, **engine_kwargs) -> None:
        self.url = url
        self.engine = make_engine(url, **engine_kwargs)
        self.is_sqlite = self.engine.dialect.name == "sqlite"
        write_bind = (
            self.engine.execution_options(sqlite_immediate=True) if self.is_sqlite else self.engine
        )
        self._read = sessionmaker(bind=self.engine, expire_on_commit=False)
        self._write = sessionmaker(bind=write_bind, expire_on_commit=False)

    @contextlib.contextmanager
    def read(self) -> Iterator[Session]:
        """Session for queries; closed (rolled back) at the end of the block."""
        with self._read() as session:
            yield session

    @contextlib.contextmanager
    def write(self) -> Iterator[Session]:
        """Session in one write transaction: commit on success, roll back on error."""
        with self._write() as session, session.begin():
            yield session

    def dispose(self) -> None:
        """Close all pooled connections."""
        self.engine.dispose()
