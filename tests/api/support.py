"""Helpers shared by the API and end-to-end tests."""

from __future__ import annotations

import atexit
import functools
import shutil
import tempfile
from pathlib import Path
from typing import Any

from app.core.security import PasswordCost
from app.settings import Settings

__all__ = ["make_settings", "migrate_database", "store_files", "create_api_key", "auth_headers", "TEST_PASSWORD_COST"]

#: Argon2's smallest cost (1 pass over 8 KiB, 1 lane): the password hashes of tests that do not
#: test the hashing (production mode refuses it)
TEST_PASSWORD_COST = PasswordCost(time_cost=1, memory_kib=8, parallelism=1)


def make_settings(tmp_path: Path, **overrides: Any) -> Settings:
    """Settings on ``tmp_path``: SQLite file ``db.sqlite``, run store ``runs/``.

    Heartbeat and stale timeout are short so that fault tests run fast. Passwords are hashed at
    :data:`TEST_PASSWORD_COST` (valid Argon2id hashes, 0.1 ms instead of 0.4-0.8 s): the tests
    of the hashing itself use the default cost (``password_hash_*`` overrides, or
    ``app.core.security.DEFAULT_PASSWORD_COST``).
    """
    values: dict[str, Any] = {
        "database_url": f"sqlite:///{tmp_path / 'db.sqlite'}",
        "run_store": tmp_path / "runs",
        "worker_poll_interval_s": 0.2,
        "worker_heartbeat_s": 0.5,
        "worker_stale_after_s": 3.0,
        "log_level": "WARNING",
        "password_hash_time_cost": TEST_PASSWORD_COST.time_cost,
        "password_hash_memory_kib": TEST_PASSWORD_COST.memory_kib,
        "password_hash_parallelism": TEST_PASSWORD_COST.parallelism,
    }
    values.update(overrides)
    return Settings(_env_file=None, **values)


def _sqlite_file(database_url: str) -> Path | None:
    """The file of a ``sqlite:///`` URL (None for another database or one in memory)."""
    prefix = "sqlite:///"
    if not database_url.startswith(prefix) or ":memory:" in database_url:
        return None
    return Path(database_url[len(prefix):])


@functools.lru_cache(maxsize=1)
def _migrated_sqlite() -> Path:
    """A SQLite file the migrations brought to head, made once per test process (removed at exit)."""
    from app.db import migrate

    folder = Path(tempfile.mkdtemp(prefix="trackvkf-migrated-"))
    atexit.register(shutil.rmtree, folder, True)
    path = folder / "head.sqlite"
    migrate.upgrade(f"sqlite:///{path}")
    leftovers = sorted(p.name for p in folder.iterdir() if p != path)
    assert not leftovers, f"the migrated database is not one file: {leftovers}"
    return path


def migrate_database(database_url: str) -> None:
    """Bring the database at ``database_url`` to the head revision, as ``app.db.migrate.upgrade``.

    A SQLite file that does not exist yet becomes a copy of one that the migrations made in this
    test process: the same file, in milliseconds instead of about a second per database (the
    migrations themselves are tested by tests/db/test_migrations.py). An existing file and any
    other database are migrated.
    """
    from app.db import migrate

    path = _sqlite_file(database_url)
    if path is None or path.exists():
        migrate.upgrade(database_url)
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(_migrated_sqlite(), path)


def store_files(root: Path) -> list[Path]:
    """All regular files below a run store root (empty directories do not count)."""
    root = Path(root)
    if not root.exists():
        return []
    return sorted(p for p in root.rglob("*") if p.is_file())


def create_api_key(database_url: str, role: str = "admin", name: str | None = None) -> str:
    """Create an API key with ``role`` in a migrated database; returns the key."""
    from app.db import auth_crud
    from app.db.session import Database

    db = Database(database_url)
    try:
        with db.write() as session:
            _, key = auth_crud.create_api_key(session, name or f"test-{role}", role, created_by="tests")
    finally:
        db.dispose()
    return key


def auth_headers(key: str) -> dict[str, str]:
    """Request headers authenticating with the API key ``key``."""
    return {"Authorization": f"Bearer {key}"}
