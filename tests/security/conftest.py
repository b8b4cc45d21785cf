"""Fixtures of the access-control tests: an app with one API key per role and a user."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.db import auth_crud
from app.db.session import Database
from app.main import create_app
from app.settings import Settings
from tests.api.support import create_api_key, make_settings, migrate_database

PASSWORD = "correct horse battery"


@dataclass
class Keys:
    """A migrated app, its settings and one API key per role."""

    settings: Settings
    client: TestClient
    keys: dict[str, str]

    def headers(self, role: str | None) -> dict[str, str]:
        return {} if role is None else {"Authorization": f"Bearer {self.keys[role]}"}


def _secured(tmp_path: Path, **overrides):
    settings = make_settings(tmp_path, **overrides)
    migrate_database(settings.database_url)
    keys = {role: create_api_key(settings.database_url, role) for role in ("viewer", "engineer", "admin")}
    db = Database(settings.database_url)
    with db.write() as session:
        for name, role in (("alice", "admin"), ("erin", "engineer"), ("vic", "viewer")):
            auth_crud.create_user(session, name, PASSWORD, role, password_cost=settings.password_cost)
    db.dispose()
    with TestClient(create_app(settings), follow_redirects=False) as client:
        yield Keys(settings=settings, client=client, keys=keys)


@pytest.fixture
def secured(tmp_path: Path):
    """An unauthenticated client on an app whose database holds a key per role and
    users ``alice`` (admin), ``erin`` (engineer) and ``vic`` (viewer)."""
    yield from _secured(tmp_path)


@pytest.fixture(scope="module")
def secured_shared(tmp_path_factory):
    """Like ``secured``, shared by a module (rate limits lifted); tests clear its cookies."""
    yield from _secured(
        tmp_path_factory.mktemp("secured"), login_rate_limit=100_000, upload_rate_limit=100_000
    )
