"""Stiffness analytics over runs and reference data (paper, section 4, and beyond): the routes.

Common query: ``line_id``, ``track``, ``run_ids`` (comma-separated; default all runs of the
line/track with results), ``km_from``, ``km_to``, ``wheel``. Missing reference data gives 200
with empty results. Amplitudes are the sleeper-passage acceleration amplitudes in m/s², the
logarithm is natural. Each route parses its query and calls one function of
:mod:`app.analytics` (correlations, speed, segments, stiffness index).
"""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Literal

from fastapi import APIRouter, Depends, Query

from app.analysis.stiffness.alignment import (
    DEFAULT_DETREND_M,
    DEFAULT_MAX_SHIFT_M,
    DEFAULT_SEGMENT_M,
)
from app.analysis.stiffness.superstructure import OUTLIER_SEGMENT_M
from app.analytics import correlations, speed
from app.analytics import segments as segments_service
from app.analytics.correlations import MAX_POINTS
from app.analytics.frames import RunsQuery, parse_run_ids
from app.analytics.stiffness_index import reference_curves_answer
from app.api.deps import (
    DbDep,
    EngineerDep,
    IdQuery,
    RunId,
    SettingsDep,
    Wheel,
    WheelQ,
    check_km,
    km_query,
    wheel_param,
)
from app.api.errors import ApiError
from app.api.reference import KmFromQ, KmToQ, LineQ, TrackQ, parse_types
from app.api.schemas.analytics import (
    AlignmentOut,
    MaintenanceOut,
    NormalisedProfileOut,
    PredictedSubsidenceOut,
    ReferenceCurvesOut,
    SegmentsOut,
    SegmentTrendOut,
    SpeedNormOut,
    SubsidenceFitOut,
    SuperstructureOut,
    UnsprungMassOut,
)
from app.core.i18n import _

__all__ = ["router"]

router = APIRouter(tags=["analytics"])

RunIdsQ = Annotated[str | None, Query(description="comma-separated run ids (default: all runs with results)")]
PointsQ = Annotated[int, Query(ge=10, le=MAX_POINTS,
                               description="scatter points returned per wheel (the fit uses all samples)")]
RefSpeedQ = Annotated[float | None, Query(gt=0, le=500, description="reference speed, km/h")]
MinSpeedQ = Annotated[float | None, Query(ge=0, le=500, description="minimum speed, km/h (default 25)")]
MaxShiftQ = Annotated[float, Query(gt=0, le=5000, description="largest shift searched, m")]
SegmentQ = Annotated[float, Query(gt=0, le=10_000)]
ValueQ = Annotated[Literal["amplitude", "index"], Query(
    description="amplitude: mean sleeper-passage amplitude (m/s²); index: mean stiffness index (ln units)")]


def _runs_query(line_id: LineQ = None, track: TrackQ = None, run_ids: RunIdsQ = None,
                km_from: KmFromQ = None, km_to: KmToQ = None, wheel: WheelQ = None) -> RunsQuery:
    """The common query (module docstring), checked: km bounds, run ids, wheel (422 naming them)."""
    check_km(km_from, km_to)
    ids = parse_run_ids(run_ids)
    return RunsQuery(line_id, track, ids, km_from, km_to, wheel_param(wheel))


RunsQ = Annotated[RunsQuery, Depends(_runs_query)]


@router.get("/analytics/subsidence-fit", response_model=SubsidenceFitOut,
            summary="Subsidence model u = a ln(Z) + b per wheel")
def subsidence_fit(db: DbDep, settings: SettingsDep, runs: RunsQ,
                   confidence: Annotated[float, Query(gt=0.5, lt=1)] = 0.95,
                   normalise: Annotated[bool, Query(
                       description="fit on the amplitude normalised to reference_speed_kmh")] = False,
                   reference_speed_kmh: RefSpeedQ = None, max_points: PointsQ = MAX_POINTS) -> dict:
    """Fit u (mm) = slope · ln(Z / 1 m/s²) + intercept on 25 cm bins with both a
    sleeper-passage amplitude Z and a subsidence value of the wheel's rail (or of both
    rails). Intervals: ``confidence`` (default 95 %), Newey–West over 100 m.
    With ``normalise`` Z is the speed-normalised amplitude (runs of different speeds pool)."""
    return correlations.subsidence_fit(db, settings, runs, confidence=confidence, normalise=normalise,
                                       reference_speed_kmh=reference_speed_kmh, max_points=max_points)


@router.get("/runs/{run_id}/predicted-subsidence", response_model=PredictedSubsidenceOut,
            summary="Subsidence predicted from a run's amplitude")
def predicted_subsidence(run_id: RunId, db: DbDep, settings: SettingsDep,
                         wheel: Wheel = "12",
                         km_from: KmFromQ = None, km_to: KmToQ = None,
                         fit_run_ids: RunIdsQ = None) -> dict:
    """u = a ln(Z) + b with a, b fitted per wheel over ``fit_run_ids`` (default all runs of
    the run's line/track with results) on the whole line; ``measured_mm`` where measured."""
    check_km(km_from, km_to)
    return correlations.predicted_subsidence(db, settings, run_id, wheel=wheel_param(wheel), km_from=km_from,
                                             km_to=km_to, fit_run_ids=parse_run_ids(fit_run_ids))


@router.get("/analytics/unsprung-mass", response_model=UnsprungMassOut,
            summary="Unsprung mass from force vs acceleration amplitude per wheel")
def unsprung_mass(db: DbDep, settings: SettingsDep, runs: RunsQ,
                  mass_min_kg: Annotated[float, Query(ge=0)] = 150.0,
                  mass_max_kg: Annotated[float, Query(gt=0)] = 600.0,
                  max_points: PointsQ = MAX_POINTS) -> dict:
    """Slope of the sleeper-passage force amplitude (kN) on the acceleration amplitude
    (m/s²) × 1000 = mass (kg); outside [mass_min_kg, mass_max_kg] → ``plausible: false``."""
    if mass_min_kg >= mass_max_kg:
        raise ApiError(422, "mass_min_kg", _("must be below mass_max_kg"))
    return correlations.unsprung_mass(db, settings, runs, mass_min_kg=mass_min_kg, mass_max_kg=mass_max_kg,
                                      max_points=max_points)


@router.get("/analytics/maintenance", response_model=MaintenanceOut,
            summary="Amplitude against the number of maintenance actions per bin")
def maintenance(db: DbDep, settings: SettingsDep, runs: RunsQ,
                type: Annotated[str | None, Query(description="comma-separated types (default all)")] = None,
                since: Annotated[dt.date | None, Query(description="actions on or after")] = None) -> dict:
    """Per 25 cm bin: the mean amplitude over the runs (and wheels) and the number of
    actions covering it; box plots per count and the regression amplitude = slope · n + intercept
    (p-value: Newey–West over 100 m)."""
    return correlations.maintenance(db, settings, runs, types=parse_types(type), since=since)


@router.get("/analytics/superstructure", response_model=SuperstructureOut,
            summary="Amplitude per superstructure type and outlying segments")
def superstructure(db: DbDep, settings: SettingsDep, runs: RunsQ,
                   segment_m: SegmentQ = OUTLIER_SEGMENT_M,
                   z_threshold: Annotated[float, Query(gt=0, le=100)] = 3.5,
                   normalise: Annotated[bool, Query(description="use the amplitude conditioned to "
                                                    "reference_speed_kmh (see conditioning)")] = True,
                   conditioning: Annotated[Literal["index", "power_law"], Query(
                       description="index: A_ref(type, v_ref) · exp(stiffness index) by the reference curves; "
                       "power_law: A · (v_ref / v) ** exponent (explicit option)")] = "index",
                   reference_speed_kmh: RefSpeedQ = None, min_speed_kmh: MinSpeedQ = None) -> dict:
    """Distribution of the amplitude per type (the paper's clusters); segments of
    ``segment_m`` whose median departs from their type by more than ``z_threshold``
    robust standard deviations are flagged for inspection. With ``normalise`` the amplitude
    is first conditioned to the reference speed (``conditioning``); types whose reference
    curve does not reach ``reference_speed_kmh`` then have no rows."""
    return speed.superstructure(db, settings, runs, segment_m=segment_m, z_threshold=z_threshold,
                                normalise=normalise, conditioning=conditioning,
                                reference_speed_kmh=reference_speed_kmh, min_speed_kmh=min_speed_kmh)


@router.get("/analytics/speed-normalisation", response_model=SpeedNormOut,
            summary="Speed exponent of the amplitude per superstructure type")
def speed_normalisation(db: DbDep, settings: SettingsDep, runs: RunsQ,
                        reference_speed_kmh: RefSpeedQ = None,
                        min_speed_kmh: MinSpeedQ = None) -> dict:
    """ln A = exponent · ln(v / v_ref) + c per type ('*' = all bins, '' = outside any
    section), estimated within bins passed at several speeds where possible. An explicit
    option (the default speed conditioning is the stiffness index): every exponent comes with
    ``stable`` and the reasons it should not be trusted."""
    return speed.speed_normalisation(db, settings, runs, reference_speed_kmh=reference_speed_kmh,
                                     min_speed_kmh=min_speed_kmh)


@router.get("/runs/{run_id}/speed-normalised-profile", response_model=NormalisedProfileOut,
            summary="A run's amplitude normalised to a reference speed")
def speed_normalised_profile(run_id: RunId, db: DbDep, settings: SettingsDep,
                             wheel: Wheel = "12", km_from: KmFromQ = None,
                             km_to: KmToQ = None, reference_speed_kmh: RefSpeedQ = None,
                             min_speed_kmh: MinSpeedQ = None, fit_run_ids: RunIdsQ = None) -> dict:
    """A · (v_ref / v) ** exponent per bin, the exponent of the bin's superstructure type
    fitted over ``fit_run_ids`` (default all runs of the line/track); null below the minimum speed."""
    check_km(km_from, km_to)
    return speed.speed_normalised_profile(db, settings, run_id, wheel=wheel_param(wheel), km_from=km_from,
                                          km_to=km_to, reference_speed_kmh=reference_speed_kmh,
                                          min_speed_kmh=min_speed_kmh, fit_run_ids=parse_run_ids(fit_run_ids))


@router.get("/runs/{run_id}/alignment", response_model=AlignmentOut,
            summary="km shift of a run against a reference run")
def run_alignment(run_id: RunId, db: DbDep, settings: SettingsDep,
                  reference_run_id: IdQuery = None,
                  max_shift_m: MaxShiftQ = DEFAULT_MAX_SHIFT_M,
                  detrend_m: Annotated[float, Query(gt=0, le=10_000)] = DEFAULT_DETREND_M) -> dict:
    """Cross-correlate the run's amplitude signature (mean over wheels) with the reference
    run's (default: the earliest run of the same line/track with results)."""
    return segments_service.run_alignment(db, settings, run_id, reference_run_id=reference_run_id,
                                          max_shift_m=max_shift_m, detrend_m=detrend_m)


@router.get("/analytics/segments", response_model=SegmentsOut,
            summary="Per-segment mean amplitude per run, mean, spread and change over runs")
def segments(db: DbDep, settings: SettingsDep, runs: RunsQ, segment_m: SegmentQ = DEFAULT_SEGMENT_M,
             align: bool = True, max_shift_m: MaxShiftQ = DEFAULT_MAX_SHIFT_M, value: ValueQ = "amplitude") -> dict:
    """Runs (by start time) are aligned to the first one (``align``), then averaged per
    segment; ``spread`` is the standard deviation over runs, ``change`` last minus first
    where the two passed at matched speed (``TRACKVKF_ANALYTICS_SPEED_TOLERANCE``; else null)."""
    return segments_service.segments(db, settings, runs, segment_m=segment_m, align=align,
                                     max_shift_m=max_shift_m, value=value)


@router.get("/analytics/segment-trend", response_model=SegmentTrendOut,
            summary="Amplitude of one segment over runs (dates)")
def segment_trend(db: DbDep, settings: SettingsDep, km: Annotated[float, km_query()],
                  line_id: LineQ = None, track: TrackQ = None, run_ids: RunIdsQ = None, wheel: WheelQ = None,
                  segment_m: SegmentQ = DEFAULT_SEGMENT_M, align: bool = True,
                  max_shift_m: MaxShiftQ = DEFAULT_MAX_SHIFT_M, value: ValueQ = "amplitude") -> dict:
    """The mean amplitude (or stiffness index) of the segment holding ``km`` in each run, by start
    time, with the run's mean speed there."""
    runs = RunsQuery(line_id, track, parse_run_ids(run_ids), None, None, wheel_param(wheel))
    return segments_service.segment_trend(db, settings, runs, km=km, segment_m=segment_m, align=align,
                                          max_shift_m=max_shift_m, value=value)


@router.get("/analytics/reference-curves", response_model=ReferenceCurvesOut,
            summary="Reference curves of the stiffness index: expected amplitude against speed per class")
def reference_curves(db: DbDep, settings: SettingsDep, line_id: LineQ = None, track: TrackQ = None) -> dict:
    """``A_ref(class, v)`` with its confidence band, from all runs of the line and track with
    results (classes: superstructure types, ``""`` = no section). Computed and cached when missing
    or stale (new results, reprocessing, imported sections)."""
    return reference_curves_answer(db, settings, line_id, track)


@router.post("/analytics/reference-curves/refresh", response_model=ReferenceCurvesOut,
             summary="Recompute the reference curves of a line and track")
def refresh_reference_curves(principal: EngineerDep, db: DbDep, settings: SettingsDep,
                             line_id: Annotated[str | None, Query(max_length=128)] = None,
                             track: TrackQ = None) -> dict:
    """Recompute the curves from all runs of the line now (also when they are current)."""
    return reference_curves_answer(db, settings, line_id, track, refresh=True)
