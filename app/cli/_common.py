"""Helpers shared by the command groups of the ``trackvkf`` command line."""

from __future__ import annotations

from typing import TYPE_CHECKING

import typer

if TYPE_CHECKING:
    from app.core.config import CoreSettings
    from app.settings import Settings

__all__ = [
    "service_settings", "core_settings", "echo", "refuse_unsafe_production", "database", "database_problem",
    "require_migrated_database", "cli_audit", "new_password",
]


def service_settings() -> Settings:
    """The service's settings (:func:`app.settings.get_settings`), imported when a command runs: the
    composition imports every package's settings group and the numerics whose constants they name,
    which ``trackvkf --help`` need not wait for."""
    from app.settings import get_settings

    return get_settings()


def core_settings() -> CoreSettings:
    """The core settings group alone (:class:`~app.core.config.CoreSettings`: the database, the run
    store; the same ``TRACKVKF_*`` variables as :func:`service_settings`), for the commands that need
    nothing else (``backup``, ``restore``): they start without importing the numerics."""
    from app.core.config import CoreSettings

    return CoreSettings()


def echo(message: str) -> None:
    """Print a line to stdout."""
    typer.echo(message, err=False)


def refuse_unsafe_production() -> None:
    """Exit with a message when production mode is configured unsafely.

    The database check (:func:`app.main.check_production_database`) is imported in production mode
    only: ``trackvkf serve`` runs it in the process that supervises the API processes, which
    serves nothing and need not load the application in development mode.
    """
    from app.core.config import ProductionConfigError

    settings = service_settings()
    try:
        settings.check_production()
        if settings.is_production:
            from app.db.session import Database
            from app.main import check_production_database

            db = Database(settings.database_url)
            try:
                check_production_database(db)
            finally:
                db.dispose()
    except ProductionConfigError as exc:
        typer.echo(f"error: refusing to start in production mode: {exc}", err=True)
        raise typer.Exit(2) from None


def database_problem(url: str) -> str | None:
    """Why the database at ``url`` cannot serve the commands yet, or None when it is migrated.

    Creates nothing: a SQLite file that does not exist (a relative URL resolved in
    another working directory, typically) is reported, not created.
    """
    from pathlib import Path

    from sqlalchemy.engine import make_url

    from app.db.migrate import current_revision

    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite" and parsed.database not in (None, "", ":memory:"):
        path = Path(parsed.database).expanduser()
        if not path.is_file():
            where = (
                f" (the URL is relative to the working directory {Path.cwd()})"
                if not path.is_absolute() else ""
            )
            return (
                f"no database at {path.resolve()}{where}. Run trackvkf from the project "
                "directory (where ./scripts/demo.sh created var/), set TRACKVKF_DATABASE_URL "
                "to your database, or create a new one here with `trackvkf migrate`"
            )
    try:
        revision = current_revision(url)
    except Exception as exc:  # noqa: BLE001 - any failure to connect is reported as a hint
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return f"cannot open the database {parsed.render_as_string(hide_password=True)}: {first}"
    if revision is None:
        return (
            f"the database {parsed.render_as_string(hide_password=True)} is not migrated: "
            "run `trackvkf migrate` first"
        )
    return None


def require_migrated_database() -> None:
    """Exit with status 2 and a one-line hint unless ``TRACKVKF_DATABASE_URL`` is migrated."""
    problem = database_problem(service_settings().database_url)
    if problem is not None:
        typer.echo(f"error: {problem}", err=True)
        raise typer.Exit(2)


def database():
    """A :class:`~app.db.session.Database` on ``TRACKVKF_DATABASE_URL`` (dispose it after use).

    Exits with a hint (status 2) when the database does not exist or is not migrated.
    """
    from app.db.session import Database

    require_migrated_database()
    return Database(service_settings().database_url)


def cli_audit(session, action: str, target: str, detail: dict | None = None) -> None:
    """Append a command-line action to the audit log (actor ``cli:<user>``)."""
    from app.audit import record
    from app.core.security import Actor

    record(session, Actor.command_line(), action, target=target, detail=detail)


def new_password() -> str:
    """A random password (16 URL-safe characters)."""
    import secrets

    return secrets.token_urlsafe(12)
