"""The audit log's writer: what a service or route changed, appended in the same transaction.

Routes and services record what they change with :func:`record` inside their own write
transaction, so an action and its audit entry are committed together::

    with db.write() as session:
        ...change...
        record(session, request, principal, "reference.import", target="maintenance",
               detail={"imported": n})

``request`` is the HTTP request (for the client address) or None (the command line). The
log is read by ``GET /api/v1/audit`` (:mod:`app.api.audit`).
"""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session

from app.core.security import Principal
from app.db import auth_crud
from app.db.session import Database

__all__ = ["ACTIONS", "record", "record_now"]

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
    "run.delete",
    "job.create",
    "job.cancel",
    "reference.import",
    "reference.delete",
    "webhook.create",
    "webhook.update",
    "webhook.delete",
    "place.status",
)


def _client_ip(request: Any) -> str | None:
    """Address of the peer of a request (the reverse proxy when there is one); None without one."""
    client = getattr(request, "client", None) if request is not None else None
    return client.host if client else None


def record(
    session: Session,
    request: Any,
    principal: Principal | None,
    action: str,
    *,
    target: Any = None,
    outcome: str = "ok",
    detail: dict[str, Any] | None = None,
    actor: str | None = None,
) -> None:
    """Append an audit entry in the caller's transaction.

    Parameters
    ----------
    session : Session
        Open write session.
    request : object or None
        The request (its ``client.host``: the client address), or None.
    principal : Principal or None
        Who acts; ``actor`` names someone not authenticated (a failed login).
    action : str
        One of :data:`ACTIONS` (e.g. ``"run.upload"``).
    target : object
        What is acted on (run id, user name, key id ...).
    outcome : str
        ``ok``, ``denied`` or ``rejected``.
    detail : dict
        Further facts (JSON).
    """
    auth_crud.audit(
        session,
        actor=actor if actor is not None else (principal.name if principal else "unknown"),
        actor_kind=principal.kind if principal else "none",
        action=action,
        target=None if target is None else str(target),
        outcome=outcome,
        client_ip=_client_ip(request),
        detail=detail,
    )


def record_now(db: Database, request: Any, principal: Principal | None, action: str, **kwargs: Any) -> None:
    """Append an audit entry in its own transaction (for outcomes without other writes)."""
    with db.write() as session:
        record(session, request, principal, action, **kwargs)
