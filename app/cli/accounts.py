"""Commands ``user`` (browser users) and ``key`` (API keys of data systems)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Annotated, Any

import typer

from app.cli._common import database, echo, new_password, service_settings

__all__ = ["user_app", "key_app"]

user_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None, help="Browser users (stored with Argon2id password hashes).")
key_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None, help="API keys of data systems (stored hashed, shown once).")


@contextlib.contextmanager
def _database() -> Iterator[Any]:
    """The database of TRACKVKF_DATABASE_URL, its connections closed after; a refused account change
    (an ``ApiError`` of :mod:`app.accounts.admin`) ends the command with its message (exit status 2)."""
    from app.core.errors import ApiError

    db = database()
    try:
        yield db
    except ApiError as exc:
        typer.echo(f"error: {exc.field}: {exc.message}", err=True)
        raise typer.Exit(2) from None
    finally:
        db.dispose()


def _password(password: str | None, generate: bool, prompt: str) -> str:
    """``password``, else a generated one (``generate``), else one asked for twice."""
    if password is not None:
        return password
    return new_password() if generate else typer.prompt(prompt, hide_input=True, confirmation_prompt=True)


@user_app.command("create")
def user_create(
    username: Annotated[str, typer.Argument(help="Login name")],
    role: Annotated[str, typer.Option(help="viewer, engineer or admin")] = "viewer",
    password: Annotated[
        str | None,
        typer.Option(help="Password (>= 10 characters); prompted when omitted, "
                     "or generated and printed with --generate"),
    ] = None,
    generate: Annotated[bool, typer.Option(help="Generate a password and print it")] = False,
) -> None:
    """Create a browser user with a role."""
    from app.accounts import admin
    from app.core.security import Actor

    password = _password(password, generate, "password")
    with _database() as db:
        admin.create_user(db, Actor.command_line(), username, password, role,
                          password_cost=service_settings().password_cost)
    echo(f"user {username} ({role}) created")
    if generate:
        echo(f"password: {password}")


@user_app.command("set-password")
def user_set_password(
    username: Annotated[str, typer.Argument(help="Login name")],
    password: Annotated[str | None, typer.Option(help="New password; prompted when omitted")] = None,
    generate: Annotated[bool, typer.Option(help="Generate a password and print it")] = False,
) -> None:
    """Set a user's password (ends its sessions; clears the demo-credentials mark)."""
    from app.accounts import admin
    from app.core.security import Actor

    password = _password(password, generate, "new password")
    with _database() as db:
        admin.update_user(db, Actor.command_line(), username, password=password,
                          password_cost=service_settings().password_cost)
    echo(f"password of {username} changed")
    if generate:
        echo(f"password: {password}")


@user_app.command("list")
def user_list() -> None:
    """List users: name, role, active, last login."""
    from app.accounts import admin

    with _database() as db:
        for u in admin.list_users(db):
            flags = ("" if u.active else " inactive") + (" demo-credentials" if u.demo_credentials else "")
            echo(f"{u.username}\t{u.role}\tlast login {u.last_login_at or '-'}{flags}")


@key_app.command("create")
def key_create(
    name: Annotated[str, typer.Argument(help="What the key is for (e.g. the data system)")],
    role: Annotated[str, typer.Option(help="viewer, engineer or admin")] = "engineer",
    expires_in_days: Annotated[int | None, typer.Option(help="Lifetime in days (default: none)")] = None,
) -> None:
    """Create an API key and print it once (only its hash is stored)."""
    from app.accounts import admin
    from app.core.security import Actor

    with _database() as db:
        row, key = admin.create_key(db, Actor.command_line(), name, role, expires_in_days)
        key_id = row.id
    typer.echo(f"API key {key_id} ({name}, {role}); shown once, keep it safe:", err=True)
    echo(key)


@key_app.command("revoke")
def key_revoke(
    key_id: Annotated[int | None, typer.Argument(help="Key id (see `trackvkf key list`)")] = None,
    name: Annotated[str | None, typer.Option(help="Instead of an id: every active key of this name")] = None,
) -> None:
    """Revoke an API key (by id, or every active key of a name)."""
    from app.accounts import admin
    from app.core.security import Actor

    if (key_id is None) == (name is None):
        raise typer.BadParameter("give a key id or --name, not both", param_hint="KEY_ID / --name")
    with _database() as db:
        if key_id is not None:
            ids = [key_id]
        else:
            ids = sorted(k.id for k in admin.list_keys(db) if k.name == name and k.revoked_at is None)
            if not ids:
                typer.echo(f"error: --name: no active API key named {name!r} (see `trackvkf key list`)", err=True)
                raise typer.Exit(2)
        for ident in ids:
            admin.revoke_key(db, Actor.command_line(), ident)
            echo(f"API key {ident} revoked")


@key_app.command("list")
def key_list() -> None:
    """List API keys: id, prefix, name, role, last use, revocation."""
    from app.accounts import admin

    with _database() as db:
        for k in admin.list_keys(db):
            state = f"revoked {k.revoked_at}" if k.revoked_at else "active"
            echo(f"{k.id}\ttvk_{k.prefix}_…\t{k.name}\t{k.role}\tlast used {k.last_used_at or '-'}\t{state}")
