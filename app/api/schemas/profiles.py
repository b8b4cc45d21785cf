"""Schemas of indicator profiles."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field

__all__ = ["ProfileOut"]


class ProfileOut(BaseModel):
    """Indicator profile of one wheel of a run.

    At ``level_m`` equal to the bin length (0.25 m) every row is one stored bin
    with the columns ``wheel, bin, km, n_samples, speed_mean`` (m/s),
    ``sleeper_amp`` (m/s², the best estimate: rail roughness out, docs/indicator.md),
    ``sleeper_amp_raw`` (m/s², the single wheel's amplitude), ``sleeper_amp_sd`` (m/s², the
    1-σ of ``sleeper_amp``), ``sleeper_amp_sd_shared`` (m/s², the part of that 1-σ shared along the
    ≈ 20 m the roughness floor is estimated over), ``order_amp_01..11`` (m/s²), ``residual_rms`` (m/s²),
    ``sleeper_force_amp`` (kN), ``track_impact_mm`` (estimated depth of an
    isolated track impact — a dipped weld or joint — in that bin, mm; null
    elsewhere), ``sleeper_step`` (m/s², the step estimate of ``sleeper_amp``: its levels between
    change points, docs/indicator.md; null where ``sleeper_amp`` is, and for a job that did not store
    it: ``step_estimate_stored`` false). At a coarser level every row is one segment with
    ``km_from, km_to, n_bins`` and ``<column>_mean``, ``<column>_max``,
    ``<column>_p95`` for every indicator column; ``sleeper_amp_sd_mean`` is the 1-σ of
    the segment's mean (the bins' errors correlate along the track, their shared part over
    ≈ 20 m), not the mean 1-σ; ``sleeper_amp_sd_shared_mean`` is the shared part of it.
    """

    run_id: int
    job_id: int | None = Field(None, description="Job whose results these are")
    wheel: str
    level_m: float
    bin_length_m: float
    km_from: float | None = None
    km_to: float | None = None
    km_extent: list[float] | None = Field(
        None,
        description="[smallest, largest] km of the wheel's whole stored profile (the full range "
        "of a zoomable plot), whatever km_from/km_to asked for",
    )
    max_points: int | None = Field(None, description="Display decimation asked for (rows kept)")
    n_rows: int
    truncated: bool = Field(False, description="True if more rows matched than returned")
    columns: list[str]
    reference: dict[str, Any] | None = Field(
        None,
        description="With index=true: the reference curves the stiffness index used (line, track, "
        "run_ids, computed_at, speed_tolerance, classes with their speed ranges), or "
        "{available: false, reason}",
    )
    step_estimate_stored: bool | None = Field(
        None,
        description="Whether the job stored the step estimate sleeper_step: false for a job processed "
        "before it was stored with the profiles (its sleeper_step is null everywhere; processing the run "
        "again stores it); null when sleeper_step was not asked for",
    )
    rows: list[dict[str, Any]] = Field(
        default_factory=list, description="The rows as objects (layout=rows, the default)"
    )
    data: dict[str, list[Any]] | None = Field(
        None,
        description="layout=columns: one array per column (same order as `columns`, the wheel "
        "left out), numbers rounded to fixed decimals: km to 6 (1 mm), others to 5 significant "
        "digits of the column's largest magnitude; null for missing values",
    )
