"""Health check (no authentication: load balancers and the demo poll it)."""

from __future__ import annotations

import logging
import os
from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter
from fastapi.responses import JSONResponse
from sqlalchemy.exc import SQLAlchemyError

from app.api.deps import DbDep, SettingsDep, StoreDep
from app.api.schemas.health import HealthOut
from app.core.diskspace import free_bytes
from app.db import crud
from app.operations.liveness import QueueHealth, queue_health

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
def health(db: DbDep, store: StoreDep, settings: SettingsDep):
    """Database reachable, run store writable with its free space, workers alive, the queue.

    ``status``: ``ok``; ``degraded`` (200) while the run store has less free
    space than ``TRACKVKF_MIN_FREE_BYTES`` (uploads get 507), while jobs are
    queued or running and no worker process is alive (heartbeats younger than
    ``TRACKVKF_WORKER_STALE_AFTER_S``), or while a running job has made no
    progress for ``TRACKVKF_HEALTH_STUCK_AFTER_S``; ``problems`` says which.
    ``unavailable`` (503) when the database or the run store cannot be used.
    """
    available = True
    queue: QueueHealth | None = None
    try:
        with db.read() as session:
            jobs = crud.queue_counts(session)
            queue = queue_health(session, stale_after_s=settings.worker_stale_after_s,
                                 stuck_after_s=settings.health_stuck_after_s)
        database = "ok"
    except SQLAlchemyError as exc:
        log.warning("health: database error %s", exc)
        jobs, database, available = {}, "unavailable", False
    free: int | None = None
    if store.root.is_dir() and os.access(store.root, os.W_OK):
        try:
            free = free_bytes(store.root)
        except OSError as exc:
            log.warning("health: cannot read the free space of %s: %s", store.root, exc)
    if free is None:
        run_store, available = "unavailable", False
    elif free < settings.min_free_bytes:
        run_store = "low_space"
        log.warning("health: run store has %d bytes free, less than TRACKVKF_MIN_FREE_BYTES", free)
    else:
        run_store = "ok"
    problems = ["run store low on space"] if run_store == "low_space" else []
    problems += queue.problems if queue is not None else []
    status = "unavailable" if not available else ("degraded" if problems else "ok")
    body = HealthOut(
        status=status,
        version=software_version(),
        database=database,
        run_store=run_store,
        run_store_free_bytes=free,
        run_store_min_free_bytes=settings.min_free_bytes,
        jobs=jobs,
        workers=_workers(queue),
        queue=None if queue is None else {"depth": queue.queued, "oldest_queued_age_s": queue.oldest_queued_age_s,
                                          "running": queue.running, "stuck": queue.stuck},
        problems=problems,
    )
    if not available:
        return JSONResponse(status_code=503, content=body.model_dump())
    return body


def _workers(queue: QueueHealth | None) -> dict | None:
    if queue is None:
        return None
    by_mode: dict[str, int] = {}
    for w in queue.workers_alive:
        by_mode[w.mode] = by_mode.get(w.mode, 0) + 1
    return {"alive": len(queue.workers_alive), "lost": queue.workers_lost, "by_mode": by_mode}
