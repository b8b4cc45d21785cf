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
           "NormalisedProfileOut", "ReferenceCurvesOut"]


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
    value: str = Field("amplitude", description="amplitude (m/s²) or index (stiffness index, ln units)")
    reference_run_id: int | None
    km: list[float]
    runs: list[SegmentRun]
    matrix: list[list[float | None]]
    mean: list[float | None]
    spread: list[float | None]
    change: list[float | None] = Field(
        description="last minus first run with data; null where their speeds differ by more than speed_tolerance")
    speed_kmh: list[list[float | None]] = Field(description="mean speed per run and segment, km/h")
    speed_tolerance: float


class TrendPoint(BaseModel):
    run_id: int
    start_time: str | None
    amplitude: float | None = Field(None, description="mean amplitude, m/s² (value=amplitude)")
    index: float | None = Field(None, description="mean stiffness index (value=index)")
    speed_kmh: float | None


class SegmentTrendOut(BaseModel):
    km: float
    segment_km: list[float]
    wheel: str | None
    value: str = "amplitude"
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
    conditioning: str | None = Field(None, description="index or power_law when normalised")
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
    stable: bool = Field(description="false: do not trust this exponent (see unstable_reasons)")
    unstable_reasons: list[str] = Field(description="interval_wide, outside_physical_range, speed_spread_small, "
                                        "pooled_confounded, not_estimable, not_power_law")
    log_speed_std: float | None = Field(description="spread of ln(v) the exponent rests on")
    power_law_misfit: float | None = Field(
        None, description="largest departure of the type's reference curve from the power law, ln units")
    plausible: bool = Field(description="exponent within the physical range (0 … 3); false when unknown")
    warning: str | None = Field(None, description="the unstable_reasons in words; null when stable")


class SpeedNormOut(BaseModel):
    reference_speed_kmh: float
    min_speed_kmh: float
    model: str = "A = A_ref * (v / v_ref) ** exponent"
    note: str = ("an explicit option: the default speed conditioning is the stiffness index "
                 "(/analytics/reference-curves, profile index=true)")
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


class ReferenceClass(BaseModel):
    """The reference curve of one class (speeds in km/h, amplitudes in m/s²)."""

    model_config = {"populate_by_name": True}

    class_: str = Field(alias="class", description="superstructure type; '' = no section (the whole line)")
    label: str
    method: str = Field(description="within (locations passed at several speeds shape it) or pooled")
    n_runs: int
    n_samples: int = Field(description="block passes (10 m, one run and wheel) used")
    n_locations: int
    spread: float | None = Field(description="location-to-location spread of the class, ln units")
    repeatability: float | None = Field(description="pass-to-pass spread of one 25 cm bin, ln units")
    confidence: float
    speed_range_kmh: list[float | None]
    speed_kmh: list[float | None]
    amplitude: list[float | None] = Field(description="A_ref at speed_kmh, m/s²")
    low: list[float | None] = Field(description="lower end of the confidence band, m/s²")
    high: list[float | None]
    log_se: list[float | None] = Field(description="standard error of ln A_ref")
    support: list[int] = Field(description="block passes within the matched-speed window")
    support_runs: list[int]


class WheelOffsetOut(BaseModel):
    wheel: str
    offset: float | None = Field(description="median ln A of the wheel against the other wheels of its rail")
    low: float | None
    high: float | None
    n_samples: int


class ReferenceCurvesOut(BaseModel):
    line_id: str
    track: str | None
    speed_tolerance: float = Field(description="matched-speed window ±tolerance × v")
    section_margin_m: float
    min_speed_kmh: float
    pooling: str
    run_ids: list[int]
    computed_at: str | None
    compute_s: float | None
    classes: list[ReferenceClass]
    wheel_offsets: list[WheelOffsetOut]
    rail_difference: float | None = Field(description="median location effect rail 2 minus rail 1, ln units")
