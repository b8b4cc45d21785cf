"""The audit log's append-only trigger and the auth tables on PostgreSQL.

Runs on a fresh database of the session's throw-away PostgreSQL cluster
(``pg_cluster`` in tests/conftest.py); the test migrates it up and back down to
base.
"""

from __future__ import annotations

import pytest
from sqlalchemy import text
from sqlalchemy.exc import DatabaseError

from app.db import auth_crud, migrate
from app.db.session import Database


def test_postgres_audit_log_is_append_only_and_keys_resolve(pg_cluster):
    if isinstance(pg_cluster, str):
        pytest.skip(pg_cluster)
    URL = pg_cluster.create_database()  # noqa: N806 - one URL per test
    migrate.upgrade(URL)
    db = Database(URL)
    try:
        with db.write() as s:
            auth_crud.audit(s, actor="x", actor_kind="user", action="auth.login")
            _, key = auth_crud.create_api_key(s, "pg", "viewer")
        with db.read() as s:
            assert auth_crud.api_key_by_token(s, key).name == "pg"
        for statement in ("UPDATE audit_log SET actor='y'", "DELETE FROM audit_log", "TRUNCATE audit_log"):
            with pytest.raises(DatabaseError, match="append-only"), db.write() as s:
                s.execute(text(statement))
        with db.read() as s:
            assert s.execute(text("SELECT actor FROM audit_log")).scalars().all() == ["x"]
    finally:
        db.dispose()
        migrate.downgrade(URL, "base")
