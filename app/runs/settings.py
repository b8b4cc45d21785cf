"""The runs' settings groups: the uploads' (``TRACKVKF_MAX_UPLOAD_BYTES``, ``TRACKVKF_UPLOAD_*``,
``TRACKVKF_PARSE_*``: how run files are received, checked and parsed, :mod:`app.runs.upload`,
:mod:`app.io.isolation`) and the workers' (``TRACKVKF_WORKER_*``, ``TRACKVKF_HEALTH_STUCK_AFTER_S``: how
workers take jobs from the queue, :mod:`app.runs.jobs`, and when a job counts as stuck)."""

from __future__ import annotations

from pydantic import Field, field_validator

from app.core.config import GIB, SettingsGroup

__all__ = ["UploadSettings", "WorkerSettings"]


class UploadSettings(SettingsGroup):
    """Uploads: how run files are received, limited and parsed.

    Attributes
    ----------
    max_upload_bytes : int
        Largest accepted upload body, bytes (default 8 GiB). Larger uploads get 413.
    upload_block_bytes : int
        Size of the blocks an upload is read and written in, bytes.
    max_metadata_bytes : int
        Largest accepted metadata JSON document, bytes.
    upload_ingest_concurrency : int
        Uploads each API process validates and converts at once (the others
        wait their turn, already received): conversion holds the GIL, and
        more at once would starve the process's reads (:mod:`app.operations.heavy`).
    upload_stale_after_s : float
        Age (s) after which an upload directory is swept at start-up on a file
        system without ``flock`` (some network file systems). Elsewhere every
        upload no live API process owns (a process holds a ``flock`` on its
        uploads) is swept at start-up, whatever its age.
    upload_rate_limit, upload_rate_window_s : int, float
        At most ``upload_rate_limit`` uploads per principal (API key or user)
        within ``upload_rate_window_s`` seconds (per API process).
    parse_isolated : bool
        Parse uploaded run files, geometries and reference files in a child
        process with a time and memory budget (default true; see
        docs/security.md, "Parsers").
    parse_seconds : float
        Wall-clock budget of one parse, s, plus the file size divided by
        ``parse_min_bytes_per_s`` (default 120 s).
    parse_min_bytes_per_s : float
        Slowest accepted parse rate, bytes/s (default 1 MB/s; a 26 MB MDF4
        file ingests at about 10–20 MB/s on one busy core).
    parse_memory_bytes : int
        Growth of a parse child's data segment, bytes (default 4 GiB).
    """

    max_upload_bytes: int = Field(default=8 * GIB, gt=0)
    upload_block_bytes: int = Field(default=1024 * 1024, ge=4096)
    max_metadata_bytes: int = Field(default=1024 * 1024, ge=1024)
    upload_ingest_concurrency: int = Field(default=1, ge=1, le=64)
    upload_stale_after_s: float = Field(default=6 * 3600.0, gt=0)
    upload_rate_limit: int = Field(default=60, ge=1)
    upload_rate_window_s: float = Field(default=3600.0, gt=0)
    parse_isolated: bool = True
    parse_seconds: float = Field(default=120.0, gt=0)
    parse_min_bytes_per_s: float = Field(default=1_000_000.0, gt=0)
    parse_memory_bytes: int = Field(default=4 * GIB, ge=64 * 1024 * 1024)


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
