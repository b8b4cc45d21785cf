"""Service settings, read from the environment with the ``TRACKVKF_`` prefix.

Every setting can be given as an environment variable (``TRACKVKF_DATABASE_URL``,
``TRACKVKF_RUN_STORE``, ...) or in a ``.env`` file in the working directory.
The API, the worker and the CLI all read the same :class:`Settings`.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings", "get_settings"]

_GIB = 1024**3


class Settings(BaseSettings):
    """Settings of the trackvkf service (API, worker, CLI).

    Attributes
    ----------
    database_url : str
        SQLAlchemy URL. ``sqlite:///./var/trackvkf.db`` (default) selects the
        embedded mode; a ``postgresql+psycopg://`` URL the production mode.
    run_store : Path
        Directory of the run store: canonical run files, uploads in progress
        and chunk results live below it.
    max_upload_bytes : int
        Largest accepted upload body, bytes (default 8 GiB). Larger uploads get 413.
    upload_block_bytes : int
        Size of the blocks an upload is read and written in, bytes.
    max_metadata_bytes : int
        Largest accepted metadata JSON document, bytes.
    upload_stale_after_s : float
        Uploads in progress older than this (s) are swept from the run store at
        start-up: they belong to a crashed or restarted API.
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
    chunk_store : str, optional
        Production mode: fsspec URL where chunk results are kept (``file:///…``,
        ``s3://bucket/prefix`` with s3fs installed, …), shared by all worker
        hosts. Default: inside the run store directory.
    anonymous_principal : str
        Name of the principal every request runs as until authentication is on.
    anonymous_role : str
        Role of that principal (viewer, engineer or admin).
    log_level : str
        Python logging level name for the service loggers.
    max_page_size : int
        Largest page a list endpoint returns.
    max_profile_rows : int
        Largest number of rows a JSON profile query returns (exports stream
        and are not limited).
    """

    model_config = SettingsConfigDict(
        env_prefix="TRACKVKF_", env_file=".env", env_file_encoding="utf-8", extra="ignore"
    )

    database_url: str = "sqlite:///./var/trackvkf.db"
    run_store: Path = Path("./var/runs")
    max_upload_bytes: int = Field(default=8 * _GIB, gt=0)
    upload_block_bytes: int = Field(default=1024 * 1024, ge=4096)
    max_metadata_bytes: int = Field(default=1024 * 1024, ge=1024)
    upload_stale_after_s: float = Field(default=6 * 3600.0, gt=0)
    worker_poll_interval_s: float = Field(default=1.0, gt=0)
    worker_heartbeat_s: float = Field(default=2.0, gt=0)
    worker_stale_after_s: float = Field(default=30.0, gt=0)
    worker_chunk_processes: int = Field(default=1, ge=1, le=64)
    chunk_store: str | None = None
    anonymous_principal: str = "local"
    anonymous_role: str = "admin"
    log_level: str = "INFO"
    max_page_size: int = Field(default=500, ge=1)
    max_profile_rows: int = Field(default=200_000, ge=1)

    @field_validator("anonymous_role")
    @classmethod
    def _check_role(cls, value: str) -> str:
        if value not in ("viewer", "engineer", "admin"):
            raise ValueError(f"anonymous_role must be viewer, engineer or admin, got {value!r}")
        return value

    @field_validator("worker_stale_after_s")
    @classmethod
    def _check_stale(cls, value: float, info) -> float:
        heartbeat = info.data.get("worker_heartbeat_s")
        if heartbeat is not None and value <= 2 * heartbeat:
            raise ValueError(
                f"worker_stale_after_s ({value}) must exceed twice worker_heartbeat_s ({heartbeat})"
            )
        return value

    @property
    def is_sqlite(self) -> bool:
        """Whether the database URL selects SQLite (embedded mode)."""
        return self.database_url.startswith("sqlite")


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """Return the process-wide settings read from the environment (cached)."""
    return Settings()
