"""Health check (no authentication: load balancers and the demo poll it)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from app.api.deps import DbDep, SettingsDep, StoreDep
from app.api.schemas.health import HealthOut
from app.operations.health import service_health

__all__ = ["router", "software_version"]

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
def health(db: DbDep, store: StoreDep, settings: SettingsDep):
    """Database reachable, run store writable with its free space, workers alive, the queue.

    ``status``: ``ok``; ``degraded`` (200) while the run store has less free
    space than ``TRACKVKF_MIN_FREE_BYTES`` (uploads get 507), while jobs are
    queued or running and no worker process is alive (heartbeats younger than
    ``TRACKVKF_WORKER_STALE_AFTER_S``), or while a running job has made no
    progress for ``TRACKVKF_HEALTH_STUCK_AFTER_S``; ``problems`` says which.
    ``unavailable`` (503) when the database or the run store cannot be used
    (:func:`app.operations.health.service_health`).
    """
    body = HealthOut(version=software_version(), **service_health(db, store, settings))
    if body.status == "unavailable":
        return JSONResponse(status_code=503, content=body.model_dump())
    return body
