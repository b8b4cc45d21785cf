"""Schemas of processing jobs."""

from __future__ import annotations

import datetime as dt
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

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


class ProcessingSettingsIn(BaseModel):
    """Settings for reprocessing a run; omitted fields keep the run's latest settings.

    See ``app.analysis.settings.ProcessingSettings`` for ranges and defaults.
    """

    model_config = ConfigDict(extra="forbid")

    n_wheel_orders: int | None = Field(None, description="Wheel orders tracked, 1..11")
    bandwidth_orders: float | None = Field(
        None, description="-3 dB bandwidth of each order's filter, in wheel orders (0.01..1)"
    )
    track_resolution_m: float | None = Field(
        None,
        description="Spatial resolution of the sleeper-passage orders: 10–90 % width of a stiffness step "
        "in their profiles, m (0.5..100); sets their bandwidth (c_q·v/resolution Hz)",
    )
    sleeper_harmonics: int | None = Field(
        None, description="Highest sleeper-passage harmonic extracted: 1 (f_s only), 2 or 3 (also 2·f_s, 3·f_s)"
    )
    force_mean_window_m: float | None = Field(
        None, description="Moving mean removed from the force channels (static load), m; 0: off"
    )
    filter_order: int | None = Field(None, description="VKF structural order q: 1, 2 or 3")
    bin_length_m: float | None = Field(None, description="Profile bin length, m")
    min_speed_kmh: float | None = Field(None, description="Slowest speed used, km/h")
    chunk_seconds: float | None = Field(None, description="Core length of a chunk, s")
