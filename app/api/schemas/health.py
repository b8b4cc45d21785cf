"""Schema of the health check."""

from __future__ import annotations

from pydantic import BaseModel

__all__ = ["HealthOut"]


class HealthOut(BaseModel):
    """Service health."""

    status: str
    version: str
    database: str
    run_store: str
    jobs: dict[str, int]
