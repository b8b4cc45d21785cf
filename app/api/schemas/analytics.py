"""Schemas of the analytics endpoints (amplitudes in m/s², km in km, subsidence in mm).

Where an analysis returns a frozen dataclass that is answered as it is (box
plots per action count, amplitude distribution per superstructure type), the
schema uses that dataclass: its fields are declared once, in the analysis.
"""

from __future__ import annotations

from pydantic import BaseModel, Field

from app.analysis.stiffness.maintenance import BoxStats
from app.analysis.stiffness.superstructure import TypeDistribution

__all__ = ["SubsidenceFitOut", "UnsprungMassOut", "MaintenanceOut", "SegmentsOut", "SegmentTrendOut",
           "SuperstructureOut", "SpeedNormOut", "AlignmentOut", "PredictedSubsidenceOut",
           "NormalisedProfileOut"]


class SubsidencePoints(BaseModel):
    amplitude: list[float]
    subsidence_mm: list[float]


class SubsidenceWheel(BaseModel):
    wheel: str
    slope: float | None = Field(description="a, mm per unit of ln(Z / 1 m/s²)")
    slope_ci: list[float | None]
    intercept: float | None = Field(description="b, mm")
    intercept_ci: list[float | None]
    rmse: float | None = Field(description="mm")
    n_samples: int
    r2: float | None
    points: SubsidencePoints


class SubsidenceFitOut(BaseModel):
    log_base: str = "e"
    amplitude_unit: str = "m/s^2"
    subsidence_unit: str = "mm"
    model: str = "u = slope * ln(Z) + intercept"
    run_ids: list[int]
    wheels: list[SubsidenceWheel]


class MassPoints(BaseModel):
    acceleration: list[float]
    force_kn: list[float]


class MassWheel(BaseModel):
    wheel: str
    mass_kg: float | None
    mass_ci: list[float | None]
    r2: float | None
    n_samples: int
    plausible: bool
    points: MassPoints


class UnsprungMassOut(BaseModel):
    plausible_range_kg: list[float]
    run_ids: list[int]
    wheels: list[MassWheel]


class Regression(BaseModel):
    slope: float | None = Field(description="m/s² per action")
    intercept: float | None = Field(description="m/s²")
    r: float | None
    p_value: float | None
    n: int


class MaintenanceOut(BaseModel):
    types: list[str]
    since: str | None
    run_ids: list[int]
    groups: list[BoxStats]
    regression: Regression


class SegmentRun(BaseModel):
    run_id: int
    start_time: str | None
    shift_m: float | None
    shift_confidence: float | None


class SegmentsOut(BaseModel):
    segment_m: float
    reference_run_id: int | None
    km: list[float]
    runs: list[SegmentRun]
    matrix: list[list[float | None]]
    mean: list[float | None]
    spread: list[float | None]
    change: list[float | None]


class TrendPoint(BaseModel):
    run_id: int
    start_time: str | None
    amplitude: float | None


class SegmentTrendOut(BaseModel):
    km: float
    segment_km: list[float]
    wheel: str | None
    points: list[TrendPoint]


class SegmentOut(BaseModel):
    section_id: int
    type: str
    km_from: float
    km_to: float
    n_bins: int
    median: float
    z: float | None
    flagged: bool


class SuperstructureOut(BaseModel):
    normalised: bool
    reference_speed_kmh: float
    run_ids: list[int]
    types: list[TypeDistribution]
    segments: list[SegmentOut]
    flagged: list[SegmentOut]


class SpeedType(BaseModel):
    type: str
    exponent: float | None
    exponent_ci: list[float | None]
    method: str = Field(description="within (same bins at several speeds), pooled or none")
    n_samples: int
    amplitude_at_ref: float | None = Field(description="median normalised amplitude, m/s²")
    plausible: bool = Field(description="exponent within the physical range (0 … 3); false when unknown")
    warning: str | None = Field(None, description="why the exponent should not be trusted")


class SpeedNormOut(BaseModel):
    reference_speed_kmh: float
    min_speed_kmh: float
    model: str = "A = A_ref * (v / v_ref) ** exponent"
    run_ids: list[int]
    types: list[SpeedType]


class AlignmentOut(BaseModel):
    run_id: int
    reference_run_id: int
    shift_m: float | None = Field(description="add to the run's positions to align it, m")
    shift_confidence: float
    peak_r: float | None
    second_r: float | None
    overlap_m: float
    lags_m: list[float]
    correlation: list[float | None]


class PredictedSubsidenceOut(BaseModel):
    run_id: int
    wheel: str
    log_base: str = "e"
    model: SubsidenceWheel | None
    fit_run_ids: list[int]
    km: list[float]
    amplitude: list[float | None]
    subsidence_mm: list[float | None]
    measured_mm: list[float | None]


class NormalisedProfileOut(BaseModel):
    run_id: int
    wheel: str
    reference_speed_kmh: float
    min_speed_kmh: float
    exponents: dict[str, float | None]
    km: list[float]
    speed_kmh: list[float | None]
    type: list[str | None]
    amplitude: list[float | None]
    amplitude_normalised: list[float | None]
