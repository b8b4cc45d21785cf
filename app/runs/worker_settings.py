"""The workers' settings group (``TRACKVKF_WORKER_*``, ``TRACKVKF_HEALTH_STUCK_AFTER_S``): how workers take
jobs from the queue (:mod:`app.runs.jobs`) and when a job counts as stuck."""

from __future__ import annotations

from pydantic import Field, field_validator

from app.core.config import SettingsGroup

__all__ = ["WorkerSettings"]


class WorkerSettings(SettingsGroup):
    """Workers: the job queue's polling, heartbeats and parallel chunks.

    Attributes
    ----------
    worker_poll_interval_s : float
        Pause of an idle worker between two looks at the queue, s.
    worker_heartbeat_s : float
        Interval at which a busy worker refreshes the heartbeat of its job, s.
    worker_stale_after_s : float
        A running job whose heartbeat is older than this (s) belongs to a dead
        worker and is claimed again.
    worker_chunk_processes : int
        Processes a worker uses to run the chunks of one job in parallel
        (default 1: in the worker process itself). Set it to the number of
        cores to process a single long run faster.
    health_stuck_after_s : float
        ``/health`` reports a running job as stuck (status ``degraded``) when
        no worker has reported progress on it for this long, s.
    """

    worker_poll_interval_s: float = Field(default=1.0, gt=0)
    worker_heartbeat_s: float = Field(default=2.0, gt=0)
    worker_stale_after_s: float = Field(default=30.0, gt=0)
    worker_chunk_processes: int = Field(default=1, ge=1, le=64)
    health_stuck_after_s: float = Field(default=600.0, gt=0)

    @field_validator("worker_stale_after_s")
    @classmethod
    def _check_stale(cls, value: float, info) -> float:
        heartbeat = info.data.get("worker_heartbeat_s")
        if heartbeat is not None and value <= 2 * heartbeat:
            raise ValueError(
                f"worker_stale_after_s ({value}) must exceed twice worker_heartbeat_s ({heartbeat})"
            )
        return value
