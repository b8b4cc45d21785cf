"""The audit log: its one writer, and its reader.

The services record what they change with :func:`record` inside their own write transaction,
so an action and its audit entry are committed together::

    with db.write() as session:
        ...change...
        record(session, actor, "reference.import", target="maintenance", detail={"imported": n})

``actor`` (:class:`app.core.security.Actor`) is who acts and from where: a route builds it
from its principal and the client's address, the command line with ``Actor.command_line()``.
The log is read by ``GET /api/v1/audit`` (:mod:`app.api.audit`) through :func:`read_log`.
"""

from __future__ import annotations

import datetime as dt
from typing import Any

from sqlalchemy.orm import Session

from app.core.security import Actor
from app.db import auth_crud
from app.db.models import AuditEntry
from app.db.session import Database

__all__ = ["ACTIONS", "record", "record_now", "read_log"]

#: Actions written to the audit log.
ACTIONS: tuple[str, ...] = (
    "auth.login",
    "auth.logout",
    "auth.password",
    "user.create",
    "user.update",
    "user.delete",
    "key.create",
    "key.revoke",
    "run.upload",
    "run.metadata",
    "run.delete",
    "job.create",
    "job.cancel",
    "reference.import",
    "reference.delete",
    "geometry.import",
    "geometry.delete",
    "channel_map.create",
    "channel_map.update",
    "channel_map.delete",
    "assets.import",
    "assets.delete",
    "webhook.create",
    "webhook.update",
    "webhook.delete",
    "place.status",
)


def record(
    session: Session,
    actor: Actor,
    action: str,
    *,
    target: Any = None,
    outcome: str = "ok",
    detail: dict[str, Any] | None = None,
) -> None:
    """Append an audit entry in the caller's transaction: the one writer of every audit row.

    Parameters
    ----------
    session : Session
        Open write session.
    actor : Actor
        Who acts and from where (:class:`app.core.security.Actor`).
    action : str
        One of :data:`ACTIONS` (e.g. ``"run.upload"``).
    target : object
        What is acted on (run id, user name, key id ...).
    outcome : str
        ``ok``, ``denied`` or ``rejected``.
    detail : dict
        Further facts (JSON).

    Raises
    ------
    ValueError
        For an action that is not one of :data:`ACTIONS`.
    """
    if action not in ACTIONS:
        raise ValueError(f"unknown audit action {action!r}; add it to app.audit.ACTIONS")
    auth_crud.audit(
        session,
        actor=actor.name,
        actor_kind=actor.kind,
        action=action,
        target=None if target is None else str(target),
        outcome=outcome,
        client_ip=actor.address,
        detail=detail,
    )


def record_now(db: Database, actor: Actor, action: str, **kwargs: Any) -> None:
    """Append an audit entry in its own transaction (for outcomes without other writes)."""
    with db.write() as session:
        record(session, actor, action, **kwargs)


def read_log(
    db: Database,
    *,
    action: str | None = None,
    actor: str | None = None,
    since: dt.datetime | None = None,
    until: dt.datetime | None = None,
    limit: int = 100,
    offset: int = 0,
) -> tuple[list[AuditEntry], int]:
    """Audit entries of the filter, newest first (detached rows), and their total count."""
    with db.read() as session:
        return auth_crud.list_audit(session, action=action, actor=actor, since=since, until=until,
                                    limit=limit, offset=offset)
