"""The audit log: the helper routes use to append to it, and its read endpoint (admin).

Routes record what they change with :func:`record` inside their own write
transaction, so an action and its audit entry are committed together::

    with db.write() as session:
        ...change...
        record(session, request, principal, "reference.import", target="maintenance",
               detail={"imported": n})
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query, Request
from sqlalchemy.orm import Session

from app.api.deps import (
    DbDep,
    PageOffset,
    Principal,
    SettingsDep,
    check_page_size,
    client_ip,
    parse_time_range,
    require_role,
)
from app.api.schemas.auth import AuditList, AuditOut
from app.db import auth_crud
from app.db.session import Database

__all__ = ["router", "record", "record_now", "ACTIONS"]

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
)

router = APIRouter(tags=["audit"], dependencies=[Depends(require_role("admin"))])


def record(
    session: Session,
    request: Request | None,
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
    request : Request or None
        The request (for the client address).
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
        client_ip=client_ip(request) if request is not None else None,
        detail=detail,
    )


def record_now(db: Database, request: Request | None, principal: Principal | None, action: str, **kwargs: Any) -> None:
    """Append an audit entry in its own transaction (for outcomes without other writes)."""
    with db.write() as session:
        record(session, request, principal, action, **kwargs)


@router.get("/audit", response_model=AuditList, summary="Read the audit log (admin)")
def read_audit(
    db: DbDep,
    settings: SettingsDep,
    action: Annotated[str | None, Query(max_length=64, description="e.g. run.upload")] = None,
    actor: Annotated[str | None, Query(max_length=128, description="User or key:<name>")] = None,
    since: Annotated[str | None, Query(max_length=40, description="ISO date or datetime")] = None,
    until: Annotated[str | None, Query(max_length=40, description="ISO date or datetime")] = None,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 100,
    offset: PageOffset = 0,
) -> AuditList:
    """Audit entries (who, when, what), newest first; append-only, nothing can change them."""
    check_page_size(limit, settings)
    start, end = parse_time_range(since, until, ("since", "until"))
    with db.read() as session:
        rows, total = auth_crud.list_audit(
            session, action=action, actor=actor, since=start, until=end, limit=limit, offset=offset
        )
        items = [AuditOut.model_validate(r) for r in rows]
    return AuditList(items=items, total=total, limit=limit, offset=offset)
