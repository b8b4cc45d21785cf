"""Schemas of runs."""

from __future__ import annotations

import datetime as dt
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from app.api.schemas.jobs import JobOut

__all__ = [
    "RunSummaryOut", "RunOut", "RunDetail", "RunList", "RunMetadataPatch", "RunMetadataChange",
    "RunMetadataOut",
]


class RunSummaryOut(BaseModel):
    """What the run file holds."""

    fs: float = Field(description="Sample rate, Hz")
    n_samples: int
    duration_s: float
    distance_m: float | None = Field(None, description="Distance covered, m")
    speed_min_kmh: float | None = Field(None, description="Lowest speed, km/h")
    speed_max_kmh: float | None = Field(None, description="Highest speed, km/h")
    channels: list[str]


class RunOut(BaseModel):
    """A run as listed."""

    id: int
    sha256: str = Field(description="sha256 of the uploaded file (hex)")
    source_format: str
    original_filename: str | None = None
    size_bytes: int
    vehicle_id: str | None = None
    line_id: str | None = None
    track: str | None = None
    direction: str | None = None
    start_time: dt.datetime | None = None
    km_start: float | None = None
    km_increasing: bool | None = None
    created_by: str | None = None
    created_at: dt.datetime
    summary: RunSummaryOut
    latest_job: JobOut | None = None
    links: dict[str, str] = Field(default_factory=dict)
    warnings: list[str] = Field(
        default_factory=list,
        description='What ingest assumed or did ("<field>: <message>"): a relative position '
        "not starting at 0, the default axle layout, GNSS outages bridged …",
    )


class RunDetail(RunOut):
    """A run with its full metadata."""

    metadata: dict[str, Any]
    ingest_report: dict[str, Any] = Field(
        default_factory=dict,
        description="Provenance from ingest: position_kind, km_source, recorder channel sources, "
        "GNSS matching and fusion summary",
    )


class RunList(BaseModel):
    """A page of runs."""

    items: list[RunOut]
    total: int
    limit: int
    offset: int


class RunMetadataPatch(BaseModel):
    """Corrected metadata fields of a run (the others keep their values)."""

    model_config = ConfigDict(extra="forbid")

    metadata: dict[str, Any] = Field(
        description="metadata fields to change, e.g. {\"line_id\": \"4010\", \"km_start\": 12.5}",
        min_length=1, max_length=64,
    )


class RunMetadataChange(BaseModel):
    """One corrected metadata field."""

    field: str
    old: Any
    new: Any


class RunMetadataOut(RunDetail):
    """The run after a metadata correction: the changed fields and the reprocessing job."""

    changed: list[RunMetadataChange]
    reprocess_job_id: int | None = Field(description="the queued job; null when nothing changed")
