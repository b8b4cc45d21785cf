"""Schemas of processing jobs."""

from __future__ import annotations

import dataclasses
import datetime as dt
import typing
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, create_model

from app.analysis.settings import ProcessingSettings, setting_help
from app.runs.jobs import N_ORDER_COLUMNS

__all__ = ["JobOut", "JobList", "ProcessingSettingsIn"]


class JobOut(BaseModel):
    """A processing job of a run."""

    id: int
    run_id: int
    status: str = Field(description="queued, running, done, failed or cancelled")
    progress: float = Field(description="Fraction of the job's chunks done, 0..1")
    error: str | None = Field(None, description="Error text of a failed job")
    settings: dict[str, Any] = Field(description="ProcessingSettings of the job")
    meta: dict[str, Any] | None = Field(
        None, description="Provenance written by the pipeline (software version, engine)"
    )
    warnings: list[str] = Field(
        default_factory=list,
        description="What the results cannot be trusted for (a record too short for its filters, orders "
        "dropped because they collide), in plain words; empty when none",
    )
    n_chunks: int | None = None
    chunks_done: int = 0
    attempts: int = Field(0, description="Number of times a worker claimed the job")
    cancel_requested: bool = False
    created_by: str | None = None
    created_at: dt.datetime
    started_at: dt.datetime | None = None
    finished_at: dt.datetime | None = None


class JobList(BaseModel):
    """A page of jobs."""

    items: list[JobOut]
    total: int
    limit: int
    offset: int


def _settings_in() -> type[BaseModel]:
    """The request body of a reprocessing job, derived from :class:`ProcessingSettings`: every setting
    optional (omitted: the run's latest value), described by its metadata; wheel orders limited to
    what the service stores (:data:`~app.runs.jobs.N_ORDER_COLUMNS`)."""
    hints = typing.get_type_hints(ProcessingSettings)
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(ProcessingSettings):
        valid = f"1..{N_ORDER_COLUMNS}: the service stores {N_ORDER_COLUMNS} order columns" \
            if f.name == "n_wheel_orders" else None
        kind = hints[f.name]
        fields[f.name] = (kind | None, Field(None, description=setting_help(f.name, valid=valid)))
    return create_model(
        "ProcessingSettingsIn",
        __config__=ConfigDict(extra="forbid"),
        __doc__="Settings for reprocessing a run; omitted fields keep the run's latest settings.\n\n"
                "Derived from ``app.analysis.settings.ProcessingSettings`` (ranges and defaults).",
        **fields,
    )


ProcessingSettingsIn = _settings_in()
