"""Users and API keys, administered by admins (and the ``trackvkf user``/``key`` commands):
each change with its audit entry in one transaction. Rows are answered detached (their columns
loaded)."""

from __future__ import annotations

import datetime as dt
from typing import Any

from app.accounts.sessions import auth_errors_as_422
from app.audit import record
from app.core.errors import ApiError
from app.core.i18n import _
from app.core.security import Actor, PasswordCost
from app.db import auth_crud
from app.db.models import ApiKey, User, utcnow
from app.db.session import Database

__all__ = ["list_users", "create_user", "update_user", "delete_user", "list_keys", "create_key", "revoke_key"]


def _is_self(actor: Actor, username: str) -> bool:
    return actor.principal is not None and actor.principal.kind == "user" and actor.name == username


def list_users(db: Database) -> list[User]:
    """All users by name."""
    with db.read() as session:
        return auth_crud.list_users(session)


def create_user(db: Database, actor: Actor, username: str, password: str, role: str, *,
                password_cost: PasswordCost) -> User:
    """Create a browser user with a role (its password stored as an Argon2id hash at
    ``password_cost``, the service's ``Settings.password_cost``).

    Raises
    ------
    ApiError
        409 (``username``) when the user exists; 422 naming a bad user name, role or password.
    """
    with db.write() as session:
        if auth_crud.get_user(session, username) is not None:
            raise ApiError(409, "username", _("user {username} exists", username=repr(username)))
        with auth_errors_as_422():
            user = auth_crud.create_user(session, username, password, role, created_by=actor.name,
                                         password_cost=password_cost)
        record(session, actor, "user.create", target=user.username, detail={"role": user.role})
        return user


def update_user(db: Database, actor: Actor, username: str, *, password_cost: PasswordCost,
                password: str | None = None, role: str | None = None, active: bool | None = None) -> User:
    """Change a user's password (hashed at ``password_cost``), role or active flag; the user's
    sessions end.

    Raises
    ------
    ApiError
        409 (``username``) for an admin deactivating or demoting itself; 404 (``username``) for
        an unknown user; 422 naming a bad role or password.
    """
    if _is_self(actor, username) and (active is False or (role is not None and role != "admin")):
        raise ApiError(409, "username", _("an admin cannot deactivate or demote itself"))
    with db.write() as session:
        with auth_errors_as_422():
            user = auth_crud.update_user(session, username, password=password, role=role, active=active,
                                         password_cost=password_cost)
        if user is None:
            raise ApiError(404, "username", _("user {username} not found", username=repr(username)))
        changed: dict[str, Any] = {k: v for k, v in (("role", role), ("active", active)) if v is not None}
        if password is not None:
            changed["password"] = "changed"
        record(session, actor, "user.update", target=username, detail=changed)
        return user


def delete_user(db: Database, actor: Actor, username: str) -> None:
    """Delete a user and end its sessions (its audit entries stay).

    Raises
    ------
    ApiError
        409 (``username``) for an admin deleting itself; 404 for an unknown user.
    """
    if _is_self(actor, username):
        raise ApiError(409, "username", _("an admin cannot delete itself"))
    with db.write() as session:
        if not auth_crud.delete_user(session, username):
            raise ApiError(404, "username", _("user {username} not found", username=repr(username)))
        record(session, actor, "user.delete", target=username)


def list_keys(db: Database) -> list[ApiKey]:
    """All API keys, newest first, with last use and revocation (never the keys themselves)."""
    with db.read() as session:
        return auth_crud.list_api_keys(session)


def create_key(db: Database, actor: Actor, name: str, role: str,
               expires_in_days: int | None = None) -> tuple[ApiKey, str]:
    """Create an API key scoped to a role: its row and the key itself (shown once; only its hash
    is kept).

    Raises
    ------
    ApiError
        422 naming a bad name or role.
    """
    expires = utcnow() + dt.timedelta(days=expires_in_days) if expires_in_days else None
    with db.write() as session:
        with auth_errors_as_422():
            row, key = auth_crud.create_api_key(session, name, role, created_by=actor.name, expires_at=expires)
        record(session, actor, "key.create", target=row.id, detail={"name": row.name, "role": row.role,
                                                                    "prefix": row.prefix})
        return row, key


def revoke_key(db: Database, actor: Actor, key_id: int) -> ApiKey:
    """Revoke an API key (it stays listed as revoked).

    Raises
    ------
    ApiError
        404 (``key_id``) for an unknown key.
    """
    with db.write() as session:
        row = auth_crud.revoke_api_key(session, key_id)
        if row is None:
            raise ApiError(404, "key_id", _("API key {key_id} not found", key_id=key_id))
        record(session, actor, "key.revoke", target=key_id, detail={"name": row.name})
        return row
