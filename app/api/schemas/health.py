"""Schema of the health check."""

from __future__ import annotations

from pydantic import BaseModel, Field

__all__ = ["HealthOut"]


class HealthOut(BaseModel):
    """Service health.

    ``status`` is ``ok``; ``degraded`` (HTTP 200) while the run store has less
    free space than ``TRACKVKF_MIN_FREE_BYTES`` (uploads are refused with 507,
    reads work); ``unavailable`` (HTTP 503) when the database or the run store
    cannot be used.
    """

    status: str = Field(description="ok, degraded (low free space) or unavailable")
    version: str
    database: str = Field(description="ok or unavailable")
    run_store: str = Field(description="ok, low_space or unavailable")
    run_store_free_bytes: int | None = Field(description="Free space of the run store's file system, bytes")
    run_store_min_free_bytes: int = Field(description="TRACKVKF_MIN_FREE_BYTES")
    jobs: dict[str, int]
