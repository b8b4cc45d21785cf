"""Fixtures of the condition tests: the databases of tests/db (SQLite, and PostgreSQL where
the test cluster can be started)."""

from tests.db.conftest import any_db, db  # noqa: F401  (fixtures)
