"""Fixtures of the db layer's tests: a migrated SQLite database, and the same on
PostgreSQL where the test cluster can be started."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from app.db.session import Database
from app.settings import Settings


@pytest.fixture
def db(service_settings: Settings) -> Iterator[Database]:
    """A :class:`Database` on a fresh, migrated SQLite file."""
    database = Database(service_settings.database_url)
    yield database
    database.dispose()


@pytest.fixture(params=["sqlite", "postgresql"])
def any_db(request: pytest.FixtureRequest) -> Iterator[Database]:
    """A fresh, migrated database of each backend: SQLite (plain inserts) and
    PostgreSQL (binary COPY; skipped where the test cluster is unavailable)."""
    if request.param == "sqlite":
        yield request.getfixturevalue("db")
        return
    from app.db import migrate

    cluster = request.getfixturevalue("pg_cluster")
    if isinstance(cluster, str):
        pytest.skip(cluster)
    url = cluster.create_database()
    migrate.upgrade(url)
    database = Database(url)
    yield database
    database.dispose()
