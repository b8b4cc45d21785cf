"""End-to-end fixtures: the real service (uvicorn + worker subprocesses on a free
loopback port) on a temporary database and run store (the simulated runs are
shared fixtures, ``tests/conftest.py``).

The ``service`` fixture runs every test twice: on SQLite (embedded mode, local
worker) and on PostgreSQL (production mode, Procrastinate workers) in a
throw-away cluster on 127.0.0.1 (:mod:`tests.pg_cluster`; the server package is
installed with apt-get if missing). The PostgreSQL variant is skipped, with
the reason, only where the server cannot be installed."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import pytest

from app.db import migrate
from tests.api.support import create_api_key, migrate_database
from tests.pg_cluster import PgCluster


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@dataclass
class Service:
    """A running API plus worker processes started by the test."""

    base_url: str
    env: dict[str, str]
    backend: str
    workdir: Path
    database_url: str
    run_store: Path
    api_key: str = ""
    api: subprocess.Popen | None = None
    workers: list[subprocess.Popen] = field(default_factory=list)
    logs: list[Path] = field(default_factory=list)
    pg: PgCluster | None = None

    def _spawn(self, args: list[str], name: str) -> subprocess.Popen:
        log = self.workdir / f"{name}-{len(self.logs)}.log"
        self.logs.append(log)
        with open(log, "wb") as fh:
            return subprocess.Popen(
                [sys.executable, *args], env=self.env, cwd=self.workdir, stdout=fh,
                stderr=subprocess.STDOUT, start_new_session=True,
            )

    def start_api(self) -> None:
        port = int(self.base_url.rsplit(":", 1)[1])
        self.api = self._spawn(
            ["-m", "uvicorn", "--factory", "app.main:create_app", "--host", "127.0.0.1",
             "--port", str(port), "--log-level", "warning"],
            "api",
        )
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if self.api.poll() is not None:
                raise RuntimeError(f"uvicorn exited:\n{self.log_text()}")
            try:
                if httpx.get(f"{self.base_url}/api/v1/health", timeout=1).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise RuntimeError(f"uvicorn did not come up:\n{self.log_text()}")

    @property
    def headers(self) -> dict[str, str]:
        """Headers authenticating as the fixture's admin API key."""
        return {"Authorization": f"Bearer {self.api_key}"}

    def client(self, **kwargs) -> httpx.Client:
        """An httpx client on the service, authenticated with the admin API key."""
        return httpx.Client(base_url=self.base_url, headers=self.headers, **kwargs)

    def kill_api(self) -> None:
        """SIGKILL the API (a crash: no clean-up of requests in flight)."""
        if self.api is not None and self.api.poll() is None:
            self.api.kill()
            self.api.wait()

    def start_worker(self) -> subprocess.Popen:
        proc = self._spawn(["-m", "worker"], "worker")
        self.workers.append(proc)
        return proc

    def log_text(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text(errors='replace')[-4000:]}" for p in self.logs if p.exists())

    def stop(self) -> None:
        procs = [p for p in [self.api, *self.workers] if p is not None]
        for p in procs:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

    def wait_job(self, client: httpx.Client, job_id: int, timeout_s: float = 240.0) -> dict:
        """Poll a job until it is final; fail with the service logs on timeout."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            job = client.get(f"/api/v1/jobs/{job_id}").json()
            if job["status"] in ("done", "failed", "cancelled"):
                return job
            time.sleep(0.3)
        raise AssertionError(f"job {job_id} not final after {timeout_s} s:\n{self.log_text()}")


@contextmanager
def running_service(
    workdir: Path,
    database_url: str | None = None,
    *,
    backend: str = "sqlite",
    pg: PgCluster | None = None,
    run_store: Path | None = None,
    env_overrides: dict[str, str] | None = None,
) -> Iterator[Service]:
    """The real service (API started, workers on demand) on a fresh database with an
    admin API key (``api_key``); stopped on exit. Shared by the ``service`` fixture
    and the browser tests.

    Parameters
    ----------
    workdir : Path
        Working directory (logs, run store; the SQLite file unless ``database_url``).
    database_url : str, optional
        Database to use (default: a new SQLite file in ``workdir``).
    backend : {"sqlite", "postgresql"}
    pg : PgCluster, optional
        The PostgreSQL cluster of ``database_url`` (for restart tests).
    run_store : Path, optional
        Run store directory (default ``workdir / "runs"``).
    env_overrides : dict, optional
        Further ``TRACKVKF_*`` settings of the API and workers.
    """
    db_url = database_url or f"sqlite:///{workdir / 'service.sqlite'}"
    migrate.upgrade(db_url)
    api_key = create_api_key(db_url, "admin", "e2e")
    env = {
        k: v for k, v in os.environ.items() if not k.startswith("TRACKVKF_")
    }
    env.update(
        {
            "TRACKVKF_DATABASE_URL": db_url,
            "TRACKVKF_RUN_STORE": str(run_store or workdir / "runs"),
            "TRACKVKF_WORKER_POLL_INTERVAL_S": "0.2",
            "TRACKVKF_WORKER_HEARTBEAT_S": "0.5",
            "TRACKVKF_WORKER_STALE_AFTER_S": "3",
            "TRACKVKF_LOG_LEVEL": "INFO",
            "PYTHONUNBUFFERED": "1",
            **(env_overrides or {}),
        }
    )
    svc = Service(
        base_url=f"http://127.0.0.1:{_free_port()}",
        env=env,
        backend=backend,
        workdir=workdir,
        database_url=db_url,
        run_store=run_store or workdir / "runs",
        api_key=api_key,
        pg=pg,
    )
    try:
        svc.start_api()
        yield svc
    finally:
        svc.stop()


class MigratedDatabases:
    """Fresh PostgreSQL databases at the migrations' head, copied from one migrated in the session.

    The ``service`` fixture's tests start on an empty database at the head; ``CREATE DATABASE ...
    TEMPLATE`` of one that the migrations made once gives that database without running every
    migration again for each test (``running_service`` still runs ``migrate.upgrade``, which finds
    nothing to do). A SQLite file is made the same way by :func:`tests.api.support.migrate_database`.
    """

    def __init__(self) -> None:
        self._pg_template: dict[int, str] = {}
        self._n = 0

    def postgresql(self, cluster: PgCluster) -> str:
        """A new migrated database in ``cluster``; returns its SQLAlchemy URL."""
        from sqlalchemy import create_engine, text
        from sqlalchemy.engine import make_url

        template = self._pg_template.get(id(cluster))
        if template is None:
            url = cluster.create_database()
            migrate.upgrade(url)
            template = self._pg_template[id(cluster)] = make_url(url).database
        self._n += 1
        name = f"e2e_{os.getpid()}_{self._n}"
        engine = create_engine(cluster.url, isolation_level="AUTOCOMMIT")
        try:
            with engine.connect() as conn:
                conn.execute(text(f'CREATE DATABASE "{name}" TEMPLATE "{template}"'))
        finally:
            engine.dispose()
        return cluster.url.rsplit("/", 1)[0] + "/" + name


@pytest.fixture(scope="session")
def migrated_databases() -> MigratedDatabases:
    """Fresh migrated PostgreSQL databases for the ``service`` fixture (:class:`MigratedDatabases`)."""
    return MigratedDatabases()


@pytest.fixture(params=["sqlite", "postgresql"])
def service(request, tmp_path, migrated_databases) -> Iterator[Service]:
    """The real service on a fresh database; the API is started, workers on demand.

    ``sqlite``: embedded mode (local worker). ``postgresql``: production mode
    (``python -m worker`` runs a Procrastinate worker). ``service.client()`` is an
    httpx client authenticated with an admin API key (``service.api_key``).
    """
    backend = request.param
    pg = None
    if backend == "postgresql":
        cluster = request.getfixturevalue("pg_cluster")
        if isinstance(cluster, str):
            pytest.skip(cluster)
        pg = cluster
        db_url = migrated_databases.postgresql(cluster)
    else:
        db_url = f"sqlite:///{tmp_path / 'service.sqlite'}"
        migrate_database(db_url)
    with running_service(tmp_path, db_url, backend=backend, pg=pg) as svc:
        yield svc


@pytest.fixture(scope="session")
def clean_reference(short_sim_run, tmp_path_factory):
    """Profile rows of a clean in-process run of the short simulation with the fault
    tests' settings (same pure pipeline the workers run), in export form."""
    import numpy as np

    from app.analysis.settings import ProcessingSettings
    from app.pipeline import run_pipeline
    from tests.e2e.support import FAULT_SETTINGS

    path, _ = short_sim_run
    settings = ProcessingSettings.from_dict(FAULT_SETTINGS)
    results = run_pipeline(path, settings, tmp_path_factory.mktemp("clean-chunks"))
    prof = results.profiles.copy()
    prof["wheel"] = prof["wheel"].astype(str)
    prof["bin"] = prof["bin"].astype(np.int64)
    return prof.sort_values(["wheel", "bin"], ignore_index=True)
