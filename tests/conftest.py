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

from app.settings import Settings
from tests.api.support import auth_headers, create_api_key, make_settings, migrate_database


@pytest.fixture(scope="session")
def datasets(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    """The tests' data sets built once and kept on disk (:class:`tests.datasets.DatasetCache`):
    simulated runs, their processing by the real pipeline, processed databases."""
    from tests.datasets import DatasetCache, cache_root

    return DatasetCache(cache_root(request.config, lambda: tmp_path_factory.mktemp("datasets")))


@pytest.fixture
def clock():
    """The service's clock moved on by the test instead of waiting (:class:`app.core.clock.OffsetClock`,
    installed for this process: in-process apps, workers and loops read it; subprocesses do not)."""
    from app.core.clock import OffsetClock, clock_in_use

    with clock_in_use(OffsetClock()) as c:
        yield c


@pytest.fixture
def service_settings(tmp_path: Path) -> Settings:
    """Settings on a fresh, migrated SQLite database in ``tmp_path`` (a copy of one migrated once per
    process: :func:`tests.api.support.migrate_database`)."""
    settings = make_settings(tmp_path)
    migrate_database(settings.database_url)
    return settings


@pytest.fixture
def make_client(tmp_path: Path) -> Iterator[Callable[..., Any]]:
    """Factory of API test clients on a migrated database; keyword arguments
    override settings (e.g. ``max_upload_bytes``). Clients are closed at teardown.

    Each client authenticates with an admin API key of its database (real
    authentication: ``client.api_key``; ``role=`` picks another role)."""
    from fastapi.testclient import TestClient

    from app.main import create_app

    clients: list[TestClient] = []

    def factory(role: str = "admin", **overrides: Any) -> TestClient:
        settings = make_settings(tmp_path, **overrides)
        migrate_database(settings.database_url)
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


def _sim_run(length_km: float) -> Callable[[Path], tuple[Path, object]]:
    def build(root: Path) -> tuple[Path, object]:
        from app.simulate.run import simulate_run

        path = root / "sim-run.h5"
        return path, simulate_run(path, length_km=length_km, fs=SIM_FS, seed=SIM_SEED, with_forces=True)

    return build


@pytest.fixture(scope="session")
def sim_run(datasets) -> tuple[Path, object]:
    """A short simulated run (1.5 km at 10 kHz, with forces) and its truth (read only: a cached data set)."""
    return datasets.get("sim-run", {"length_km": SIM_LENGTH_KM}, _sim_run(SIM_LENGTH_KM))


@pytest.fixture(scope="session")
def short_sim_run(datasets) -> tuple[Path, object]:
    """A shorter simulated run (0.8 km, ~36 s at 10 kHz) for the fault tests (read only: cached)."""
    return datasets.get("sim-run", {"length_km": 0.8}, _sim_run(0.8))


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


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object:
    """Units of work and their order for the xdist workers (tests/xdist_schedule.py)."""
    from tests.xdist_schedule import make_scheduler

    return make_scheduler(config, log)


#: the demo data set of the tests (app.simulate.demo): runs of this length (km) and sample rate (Hz)
DEMO_LENGTH_KM = 1.2
DEMO_FS = 10_000.0


def _demo_dataset(root: Path):
    from app.simulate.demo import write_demo_dataset

    return write_demo_dataset(root, length_km=DEMO_LENGTH_KM, fs=DEMO_FS)


@pytest.fixture(scope="session")
def demo_data(datasets):
    """The demo's data set (``app.simulate.demo.write_demo_dataset``: 4 runs of 1.2 km at 10 kHz on
    two lines, reference data of line SIM, both lines' geometry), written once (a cached data set:
    read only)."""
    return datasets.get("demo-files", {"length_km": DEMO_LENGTH_KM, "fs": DEMO_FS}, _demo_dataset)


@pytest.fixture(scope="session")
def processed_demo(datasets, demo_data):
    """The demo data set uploaded and processed once (:mod:`tests.demo_db`: a SQLite database and its
    run store, cached); tests work on a copy (``processed_demo.copy_to(dir)``)."""
    from tests.demo_db import build_processed_demo

    return datasets.get("demo-processed", {"length_km": DEMO_LENGTH_KM, "fs": DEMO_FS},
                        lambda root: build_processed_demo(root, demo_data))


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
