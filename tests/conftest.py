"""Shared fixtures: service settings on a temporary SQLite file and run store, an
API test client on a migrated database, a view of the run store's files, and
simulated runs (``sim_run``, ``short_sim_run``).

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


SIM_LENGTH_KM = 1.5
SIM_FS = 10_000.0
SIM_SEED = 1


@pytest.fixture(scope="session")
def sim_run(tmp_path_factory) -> tuple[Path, object]:
    """A short simulated run (1.5 km at 10 kHz, with forces) and its truth."""
    from app.simulate.run import simulate_run

    path = tmp_path_factory.mktemp("sim") / "sim-run.h5"
    truth = simulate_run(path, length_km=SIM_LENGTH_KM, fs=SIM_FS, seed=SIM_SEED, with_forces=True)
    return path, truth


@pytest.fixture(scope="session")
def short_sim_run(tmp_path_factory) -> tuple[Path, object]:
    """A shorter simulated run (0.8 km, ~36 s at 10 kHz) for the fault tests."""
    from app.simulate.run import simulate_run

    path = tmp_path_factory.mktemp("sim-short") / "sim-short.h5"
    truth = simulate_run(path, length_km=0.8, fs=SIM_FS, seed=SIM_SEED, with_forces=True)
    return path, truth


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


#: the demo data set of the tests (app.simulate.demo): runs of this length (km) and sample rate (Hz)
DEMO_LENGTH_KM = 1.2
DEMO_FS = 10_000.0


@pytest.fixture(scope="session")
def demo_data(tmp_path_factory):
    """The demo's data set (``app.simulate.demo.write_demo_dataset``: 4 runs of 1.2 km at 10 kHz on
    two lines, reference data of line SIM, both lines' geometry), written once per session."""
    from app.simulate.demo import write_demo_dataset

    return write_demo_dataset(tmp_path_factory.mktemp("demo"), length_km=DEMO_LENGTH_KM, fs=DEMO_FS)


@pytest.fixture(scope="session")
def browser() -> Iterator[object]:
    """Headless Debian chromium driven by Playwright (no Playwright browser download): one for the
    whole session, shared by every browser test (a second Playwright in the same thread would
    refuse to start while the first runs)."""
    from playwright.sync_api import sync_playwright

    from tests.dashboard.conftest import CHROMIUM, CHROMIUM_ARGS, _install_chromium

    _install_chromium()
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()
