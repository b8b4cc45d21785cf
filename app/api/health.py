"""Health check (no authentication: load balancers and the demo poll it)."""

from __future__ import annotations

import logging
import os
from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter
from fastapi.responses import JSONResponse
from sqlalchemy.exc import SQLAlchemyError

from app.api.deps import DbDep, StoreDep
from app.api.schemas.health import HealthOut
from app.db import crud

__all__ = ["router", "software_version"]

log = logging.getLogger(__name__)

router = APIRouter(tags=["health"])


def software_version() -> str:
    """Installed version of trackvkf."""
    try:
        return version("trackvkf")
    except PackageNotFoundError:
        return "unknown"


@router.get(
    "/health",
    response_model=HealthOut,
    summary="Service health",
    responses={503: {"description": "Database or run store unavailable"}},
)
def health(db: DbDep, store: StoreDep):
    """Database reachable, run store writable, and the number of jobs per status."""
    ok = True
    try:
        with db.read() as session:
            jobs = crud.queue_counts(session)
        database = "ok"
    except SQLAlchemyError as exc:
        log.warning("health: database error %s", exc)
        jobs, database, ok = {}, "unavailable", False
    store_ok = store.root.is_dir() and os.access(store.root, os.W_OK)
    ok = ok and store_ok
    body = HealthOut(
        status="ok" if ok else "degraded",
        version=software_version(),
        database=database,
        run_store="ok" if store_ok else "unavailable",
        jobs=jobs,
    )
    if not ok:
        return JSONResponse(status_code=503, content=body.model_dump())
    return body
