"""The audit log's read endpoint (admin). Entries are written by :func:`app.audit.record`
(re-exported here for the routes), in the transaction of the change they record."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Query

from app.api.deps import (
    DbDep,
    PageOffset,
    SettingsDep,
    check_page_size,
    parse_time_range,
    require_role,
)
from app.api.schemas.auth import AuditList, AuditOut
from app.audit import ACTIONS, record, record_now
from app.db import auth_crud

__all__ = ["router", "record", "record_now", "ACTIONS"]

router = APIRouter(tags=["audit"], dependencies=[Depends(require_role("admin"))])


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
