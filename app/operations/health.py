"""The service's health as ``GET /health`` answers it: the database reachable, the run store
writable with its free space, the workers alive and the queue (:mod:`app.operations.liveness`).

``status``: ``ok``; ``degraded`` while the run store has less free space than
``TRACKVKF_MIN_FREE_BYTES`` (uploads get 507), while jobs are queued or running and no worker
process is alive (heartbeats younger than ``TRACKVKF_WORKER_STALE_AFTER_S``), or while a
running job has made no progress for ``TRACKVKF_HEALTH_STUCK_AFTER_S``; ``problems`` says
which. ``unavailable`` when the database or the run store cannot be used.
"""

from __future__ import annotations

import logging
import os
from typing import Any

from sqlalchemy.exc import SQLAlchemyError

from app.core.diskspace import free_bytes
from app.core.runstore import RunStore
from app.db import crud
from app.db.session import Database
from app.operations.liveness import QueueHealth, queue_health
from app.settings import Settings

__all__ = ["service_health"]

log = logging.getLogger(__name__)


def _workers(queue: QueueHealth | None) -> dict | None:
    if queue is None:
        return None
    by_mode: dict[str, int] = {}
    for w in queue.workers_alive:
        by_mode[w.mode] = by_mode.get(w.mode, 0) + 1
    return {"alive": len(queue.workers_alive), "lost": queue.workers_lost, "by_mode": by_mode}


def service_health(db: Database, store: RunStore, settings: Settings) -> dict[str, Any]:
    """The health answer's fields (all but ``version``): ``status``, ``database``, ``run_store``,
    its free and minimum free bytes, ``jobs`` per status, ``workers``, ``queue`` and ``problems``."""
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
    return {
        "status": status, "database": database, "run_store": run_store, "run_store_free_bytes": free,
        "run_store_min_free_bytes": settings.min_free_bytes, "jobs": jobs, "workers": _workers(queue),
        "queue": None if queue is None else {"depth": queue.queued, "oldest_queued_age_s": queue.oldest_queued_age_s,
                                             "running": queue.running, "stuck": queue.stuck},
        "problems": problems,
    }
