"""Shared fixtures: service settings on a temporary SQLite file and run store, an
API test client on a migrated database, and a view of the run store's files.

The fixtures are opt-in (no autouse): numerical tests do not pay for them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from app.core.config import Settings
from tests.api.support import auth_headers, create_api_key, make_settings


@pytest.fixture
def service_settings(tmp_path: Path) -> Settings:
    """Settings on a fresh, migrated SQLite database in ``tmp_path``."""
    from app.db import migrate

    settings = make_settings(tmp_path)
    migrate.upgrade(settings.database_url)
    return settings


@pytest.fixture
def make_client(tmp_path: Path) -> Iterator[Callable[..., Any]]:
    """Factory of API test clients on a migrated database; keyword arguments
    override settings (e.g. ``max_upload_bytes``). Clients are closed at teardown.

    Each client authenticates with an admin API key of its database (real
    authentication: ``client.api_key``; ``role=`` picks another role)."""
    from fastapi.testclient import TestClient

    from app.db import migrate
    from app.main import create_app

    clients: list[TestClient] = []

    def factory(role: str = "admin", **overrides: Any) -> TestClient:
        settings = make_settings(tmp_path, **overrides)
        migrate.upgrade(settings.database_url)
        key = create_api_key(settings.database_url, role)
        client = TestClient(create_app(settings), headers=auth_headers(key))
        client.__enter__()
        client.settings = settings  # type: ignore[attr-defined]
        client.api_key = key  # type: ignore[attr-defined]
        clients.append(client)
        return client

    yield factory
    for client in clients:
        client.__exit__(None, None, None)


@pytest.fixture
def client(make_client):
    """API test client with default test settings."""
    return make_client()


@pytest.fixture(scope="session")
def pg_cluster():
    """A throw-away PostgreSQL cluster on 127.0.0.1 for the session (tests/pg_cluster.py),
    or, where the server cannot be installed, the reason as a string (tests skip with it)."""
    from tests.pg_cluster import PgCluster, PgUnavailable

    try:
        cluster = PgCluster().init()
    except (PgUnavailable, RuntimeError, OSError) as exc:
        yield f"PostgreSQL unavailable: {exc}"
        return
    try:
        yield cluster
    finally:
        cluster.destroy()


def pytest_configure(config: pytest.Config) -> None:
    # fastapi.testclient works with httpx; the suggestion to use httpx2 is noise here
    config.addinivalue_line(
        "filterwarnings", "ignore:Using `httpx` with `starlette.testclient`"
    )
