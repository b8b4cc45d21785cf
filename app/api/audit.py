"""The audit log's read endpoint (admin). Entries are written by :func:`app.audit.record`, by
the services, in the transaction of the change they record."""

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
from app.audit import read_log

__all__ = ["router"]

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
    rows, total = read_log(db, action=action, actor=actor, since=start, until=end, limit=limit, offset=offset)
    return AuditList(items=[AuditOut.model_validate(r) for r in rows], total=total, limit=limit, offset=offset)
