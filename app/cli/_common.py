"""Helpers shared by the command groups of the ``trackvkf`` command line."""

from __future__ import annotations

import os

import typer

from app.core.config import get_settings

__all__ = ["CLI_ACTOR", "echo", "refuse_unsafe_production", "database", "cli_audit", "new_password"]

#: ``created_by`` of users and keys made on the command line
CLI_ACTOR = "cli"


def echo(message: str) -> None:
    """Print a line to stdout."""
    typer.echo(message, err=False)


def refuse_unsafe_production() -> None:
    """Exit with a message when production mode is configured unsafely."""
    from app.core.config import ProductionConfigError
    from app.db.session import Database
    from app.main import check_production_database

    settings = get_settings()
    try:
        settings.check_production()
        if settings.is_production:
            db = Database(settings.database_url)
            try:
                check_production_database(db)
            finally:
                db.dispose()
    except ProductionConfigError as exc:
        typer.echo(f"error: refusing to start in production mode: {exc}", err=True)
        raise typer.Exit(2) from None


def database():
    """A :class:`~app.db.session.Database` on ``TRACKVKF_DATABASE_URL`` (dispose it after use)."""
    from app.db.session import Database

    return Database(get_settings().database_url)


def cli_audit(session, action: str, target: str, detail: dict | None = None) -> None:
    """Append a command-line action to the audit log (actor ``cli:<user>``)."""
    from app.db import auth_crud

    auth_crud.audit(
        session, actor=f"{CLI_ACTOR}:{os.environ.get('USER', 'unknown')}", actor_kind="cli",
        action=action, target=target, detail=detail,
    )


def new_password() -> str:
    """A random password (16 URL-safe characters)."""
    import secrets

    return secrets.token_urlsafe(12)
