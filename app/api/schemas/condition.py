"""Schemas of the condition endpoints (index in natural-log units, km in km, speeds in km/h).

``condition_index`` in these answers is the store's **condition index**, ``ln(A / 1 m/s²)`` of the
sleeper-passage amplitude, compared at matched speed (the heat map names it: ``"ln_amplitude"``);
it is not the **stiffness index** ``ln(A / A_ref(class, v))`` of the profiles (``stiffness_index``
with ``index=true``), the analytics (``value=index``) and the places. Until issue 31 these keys were
``index`` (docs/api.md, "Renamed").
"""

from __future__ import annotations

from pydantic import BaseModel, Field

__all__ = [
    "ConditionLineOut",
    "ConditionLinesOut",
    "HeatmapRun",
    "HeatmapOut",
    "TrendWheel",
    "TrendPoint",
    "TrendAction",
    "TrendOut",
    "FlagOut",
    "ChangesOut",
    "FlagFeedOut",
]


class ConditionLineOut(BaseModel):
    line_id: str
    track: str
    km_min: float | None = Field(description="start of the stored segments, km")
    km_max: float | None = Field(description="end of the stored segments, km")
    n_runs: int
    first_run: str | None
    last_run: str | None
    last_run_id: int | None
    last_run_flags: int
    reference_run_id: int | None = Field(description="run whose signature the other runs are aligned onto")


class ConditionLinesOut(BaseModel):
    items: list[ConditionLineOut]


class HeatmapRun(BaseModel):
    run_id: int
    start_time: str
    shift_m: float = Field(description="alignment shift applied to the run, m")
    n_flags: int


class HeatmapOut(BaseModel):
    line_id: str
    track: str
    segment_m: int
    wheel: str | None = Field(description="null: mean over the wheels")
    condition_index: str = Field(description="which index the values are (provenance): \"ln_amplitude\", the "
                                 "condition index ln(A / 1 m/s²) compared at matched speed")
    km: list[float] = Field(description="segment starts, km")
    runs: list[HeatmapRun]
    matrix: list[list[float | None]] = Field(description="condition index per run (row, oldest first) and segment")
    flagged: list[list[int]] = Field(description="[row, column] of cells holding a flag of the run")


class TrendWheel(BaseModel):
    wheel: str
    condition_index: float = Field(description="ln A of the wheel over the segment (log units)")
    condition_index_sd: float | None = Field(description="stated 1-σ of the condition index from the profile's sleeper_amp_sd "
                                   "(roughness, noise, too few sleeper bays; log units); null: none stated")
    amp_mean: float = Field(description="m/s²")
    amp_p95: float = Field(description="m/s²")
    speed_kmh: float
    n_valid: int
    n_history: int
    change: float | None
    change_z: float | None
    trend_rate_per_year: float | None = Field(description="trend test's rate of the index, ln units a year (the "
                                                          "amplitude's change a year: 100 · expm1 of it, %)")
    trend_z: float | None


class TrendPoint(BaseModel):
    run_id: int
    start_time: str
    condition_index: float | None = Field(description="mean over the wheels")
    relative: float | None = Field(description="condition index minus the run's mean around the segment "
                                   "(TRACKVKF_PLACES_EFFECT_AROUND_M, …_MARGIN_M; log units)")
    flagged: bool
    wheels: list[TrendWheel]


class TrendAction(BaseModel):
    id: int
    type: str
    date: str
    km_from: float
    km_to: float


class TrendOut(BaseModel):
    line_id: str
    track: str
    segment_m: int
    segment_km: list[float] = Field(description="[from, to], km")
    points: list[TrendPoint]
    maintenance: list[TrendAction] = Field(description="maintenance actions over the segment")


class FlagOut(BaseModel):
    id: int = Field(description="feed cursor: increases in commit order")
    run_id: int
    line_id: str
    track: str
    km_from: float
    km_to: float
    segment_m: int
    kind: str = Field(description="step (sudden change) or trend (gradual)")
    direction: str = Field(description="up (index rose: stiffer / higher amplitude) or down")
    score: float = Field(description="combined score over the wheels, in repeatability units")
    change: float | None = Field(description="change of the index against the baseline (log units)")
    change_pct: float | None = Field(description="the same as a percentage of the amplitude")
    rate_per_year: float | None = Field(description="trend of the index, ln units a year (the amplitude's "
                                                            "change a year: 100 · expm1 of it, %)")
    wheels: list[str] = Field(description="wheels that agree")
    is_new: bool = Field(description="not flagged by the same test and direction in the line's previous run")
    created_at: str


class ChangesOut(BaseModel):
    run_id: int
    line_id: str
    track: str
    start_time: str
    shift_m: float
    history_runs: int | None
    items: list[FlagOut]


class FlagFeedOut(BaseModel):
    items: list[FlagOut]
    next_since: int = Field(description="pass as since= to get the flags after these")


class EffectOut(BaseModel):
    action_id: int
    line_id: str
    track: str
    type: str
    date: str
    km_from: float
    km_to: float
    n_runs: int = Field(description="runs of the line over the action's extent (0: no before/after view)")
    n_runs_before: int
    n_runs_after: int
    condition_index_before: float | None = Field(description="median condition index over the extent before, "
                                                             "relative to the track of its class around it at its "
                                                             "speed in each run (log units)")
    condition_index_after: float | None = Field(description="the same just after")
    sign_convention: str = Field(description="every change is after minus before, ln units of the amplitude "
                                             "(_pct: 100 * expm1); negative = lower amplitude")
    interval: str = Field(description="what the _low / _high fields span: 1 sigma (68 %)")
    recovery: float | None = Field(description="the support's change: each run after against the runs before at "
                                               "its speed (a tamping); a grinding or rail renewal: since the work, "
                                               "against the new surface's own baseline (log units)")
    recovery_pct: float | None = Field(description="the recovery as a percentage of the amplitude")
    recovery_low: float | None = Field(description="recovery minus its 1 sigma")
    recovery_high: float | None = Field(description="recovery plus its 1 sigma")
    support_change: float | None = Field(description="the support's change (= recovery)")
    support_change_pct: float | None
    rail_surface: bool = Field(description="the action changes the rails' running surface (grinding, rail renewal)")
    rail_surface_change: float | None = Field(description="the rail surface's response change across the work, "
                                                          "at matched speed (rail-surface actions only)")
    rail_surface_change_pct: float | None
    rail_surface_change_low: float | None = Field(description="rail_surface_change minus its 1 sigma")
    rail_surface_change_high: float | None = Field(description="rail_surface_change plus its 1 sigma")
    slope_after_per_year: float | None = Field(description="index change after the action, ln units a year")
    lasted_days_observed: float | None = Field(description="days until the given fraction of the change across the "
                                                           "work was lost (a rail-surface action: of the rail "
                                                           "surface's change)")
    lasted_days_projected: float | None = Field(description="the same projected from the slope after; only within "
                                                            "followed_days (never beyond the runs seen)")
    followed_days: float | None = Field(description="days from the action to the last run after it")


class EffectsOut(BaseModel):
    regain_fraction: float
    items: list[EffectOut]


class SeriesPoint(BaseModel):
    run_id: int
    start_time: str
    condition_index: float = Field(description="over the extent, relative to its surroundings (log units)")


class EffectDetailOut(EffectOut):
    series: list[SeriesPoint] = Field(description="index over the extent per run relative to its surroundings, "
                                              "oldest first")
    profile_km: list[float] = Field(description="segment starts (km) of the extent ± 100 m")
    profile_before: list[float | None] = Field(description="mean relative index per segment over the runs before")
    profile_after: list[float | None] = Field(description="mean index per segment over the runs just after")
