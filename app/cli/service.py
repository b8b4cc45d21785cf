"""Service commands: ``serve`` (REST API), ``worker`` (processing), ``migrate`` (database)."""

from __future__ import annotations

import os
from typing import Annotated

import typer

from app.cli._common import (
    echo,
    refuse_unsafe_production,
    require_migrated_database,
    service_settings,
)
from app.core.logging import configure_logging

__all__ = ["serve", "worker", "migrate", "default_api_workers"]


def default_api_workers() -> int:
    """API processes ``serve`` starts by default: one per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def serve(
    host: Annotated[str, typer.Option(help="Interface to listen on")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port")] = 8000,
    log_level: Annotated[str, typer.Option(help="uvicorn log level")] = "info",
    workers: Annotated[
        int | None,
        typer.Option(min=1, max=64, help="API processes (default: one per core)"),
    ] = None,
) -> None:
    """Run the REST API (uvicorn). Migrate the database first (``trackvkf migrate``).

    Several API processes share the port (uvicorn restarts one that dies); on
    SQLite they read side by side (WAL) and take turns writing. Each process
    keeps its own in-process rate limits and profile answer cache.

    With ``TRACKVKF_ENV=production`` it refuses to start without a secret key
    of its own or while a user still has the password printed by ``demo``.
    """
    import uvicorn

    from app.observability.multiproc import prepare_multiprocess_dir, remove_multiprocess_dir

    metrics_dir, made = prepare_multiprocess_dir()  # /metrics adds up the counts of every API process
    try:
        require_migrated_database()
        refuse_unsafe_production()
        n = workers if workers is not None else default_api_workers()
        uvicorn.run(
            "app.main:create_app", factory=True, host=host, port=port, log_level=log_level.lower(),
            workers=n, timeout_graceful_shutdown=30,
        )
    finally:
        if made:
            remove_multiprocess_dir(metrics_dir)


def worker(
    once: Annotated[bool, typer.Option(help="Exit after one job (local mode)")] = False,
    exit_when_idle: Annotated[bool, typer.Option(help="Exit when no job is queued")] = False,
    processes: Annotated[
        int, typer.Option(help="PostgreSQL mode: worker processes (0 = one per core)")
    ] = 1,
    local: Annotated[bool, typer.Option(help="Local job loop even on PostgreSQL")] = False,
) -> None:
    """Process queued jobs until Ctrl-C: the local worker on SQLite, Procrastinate
    workers on PostgreSQL (mode from TRACKVKF_DATABASE_URL)."""
    from worker import modes

    settings = service_settings()
    require_migrated_database()
    configure_logging(settings.log_level, settings.log_format)
    code = modes.run(settings, local=local, once=once, exit_when_idle=exit_when_idle, processes=processes)
    if code:
        raise typer.Exit(code)


def migrate(
    revision: Annotated[str, typer.Option(help="Target revision")] = "head",
) -> None:
    """Apply the database migrations (Alembic) to TRACKVKF_DATABASE_URL."""
    from app.db import migrate as db_migrate

    settings = service_settings()
    db_migrate.upgrade(settings.database_url, revision)
    echo(f"database {settings.database_url} at {db_migrate.current_revision(settings.database_url)}")

