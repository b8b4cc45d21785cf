"""Schema of the health check."""

from __future__ import annotations

from pydantic import BaseModel, Field

__all__ = ["HealthOut", "WorkersOut", "QueueOut"]


class WorkersOut(BaseModel):
    """Worker processes (both modes report a heartbeat)."""

    alive: int = Field(description="Worker processes alive")
    lost: int = Field(description="Worker processes silent for longer than TRACKVKF_WORKER_STALE_AFTER_S "
                                  "(died without stopping; forgotten after a day)")
    by_mode: dict[str, int] = Field(description="Worker processes alive per mode: local (the local job loop), "
                                               "procrastinate")


class QueueOut(BaseModel):
    """The job queue."""

    depth: int = Field(description="Jobs queued")
    oldest_queued_age_s: float | None = Field(description="Age of the oldest queued job, s (null: none queued)")
    running: int = Field(description="Jobs running")
    stuck: int = Field(description="Running jobs without progress for TRACKVKF_HEALTH_STUCK_AFTER_S")


class HealthOut(BaseModel):
    """Service health.

    ``status`` is ``ok``; ``degraded`` (HTTP 200) while the run store has less
    free space than ``TRACKVKF_MIN_FREE_BYTES`` (uploads are refused with 507,
    reads work), while jobs wait and no worker is alive, or while a running job
    makes no progress (``problems`` says which); ``unavailable`` (HTTP 503)
    when the database or the run store cannot be used.
    """

    status: str = Field(description="ok, degraded (see problems) or unavailable")
    version: str
    database: str = Field(description="ok or unavailable")
    run_store: str = Field(description="ok, low_space or unavailable")
    run_store_free_bytes: int | None = Field(description="Free space of the run store's file system, bytes")
    run_store_min_free_bytes: int = Field(description="TRACKVKF_MIN_FREE_BYTES")
    jobs: dict[str, int]
    workers: WorkersOut | None = Field(default=None, description="Worker processes (null: database unavailable)")
    queue: QueueOut | None = Field(default=None, description="The job queue (null: database unavailable)")
    problems: list[str] = Field(default_factory=list, description="Why the status is not ok")
