"""Stiffness analytics over runs and reference data (paper, section 4, and beyond).

Common query: ``line_id``, ``track``, ``run_ids`` (comma-separated; default
all runs of the line/track with results), ``km_from``, ``km_to``. Missing
reference data gives 200 with empty results. Amplitudes are the
sleeper-passage acceleration amplitudes in m/s², the logarithm is natural.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
import pandas as pd
from fastapi import APIRouter, Depends, Query

from app.analysis.stiffness.alignment import align_runs, segment_table
from app.analysis.stiffness.maintenance import count_actions, maintenance_correlation
from app.analysis.stiffness.regression import decimate_indices
from app.analysis.stiffness.speed_norm import MAX_POWER_LAW_MISFIT
from app.analysis.stiffness.subsidence import (
    LOG_BASE,
    bin_means,
    fit_subsidence,
    predict_subsidence,
)
from app.analysis.stiffness.superstructure import flag_segments, type_distributions
from app.analysis.stiffness.unsprung_mass import fit_unsprung_mass
from app.api import analytics_data as data
from app.api.analytics_index import curve_misfits, index_context
from app.api.deps import DbDep, RunId, SettingsDep, check_km, km_query
from app.api.errors import ApiError, not_found
from app.api.profiles import run_with_results
from app.api.reference import KmFromQ, KmToQ, LineQ, TrackQ, parse_types
from app.api.schemas.analytics import (
    AlignmentOut,
    MaintenanceOut,
    NormalisedProfileOut,
    PredictedSubsidenceOut,
    SegmentsOut,
    SegmentTrendOut,
    SpeedNormOut,
    SubsidenceFitOut,
    SuperstructureOut,
    UnsprungMassOut,
)
from app.db import crud
from app.db import reference_curves as curves_db
from app.db.session import Database

__all__ = ["router"]

router = APIRouter(tags=["analytics"])

RunIdsQ = Annotated[str | None, Query(description="comma-separated run ids (default: all runs with results)")]
WheelQ = Annotated[str | None, Query(pattern=r"^[0-9A-Za-z]{1,8}$", description="wheel (default all)")]
_MAX_POINTS = 5000
PointsQ = Annotated[int, Query(ge=10, le=_MAX_POINTS,
                               description="scatter points returned per wheel (the fit uses all samples)")]
_WHEELS = ("11", "12", "41", "42")
RefSpeedQ = Annotated[float | None, Query(gt=0, le=500, description="reference speed, km/h")]
MinSpeedQ = Annotated[float | None, Query(ge=0, le=500, description="minimum speed, km/h (default 25)")]


def _wheel(w: str | None) -> str | None:
    if w is None:
        return None
    w = w[1:] if w[:1] in ("Z", "z") else w
    if w not in _WHEELS:
        raise ApiError(422, "wheel", f"must be one of {', '.join(_WHEELS)} (or Z11 …), got {w!r}")
    return w


def _sel(db, line_id, track, run_ids, km_from, km_to):
    check_km(km_from, km_to)
    return data.select_runs(db, line_id, track, data.parse_run_ids(run_ids))


@dataclass(frozen=True)
class _Runs:
    """The common query of the analytics over runs (module docstring), as given."""

    line_id: str | None
    track: str | None
    run_ids: str | None
    km_from: float | None
    km_to: float | None
    wheel: str | None

    def select(self, db: Database) -> data.Selection:
        """The selected runs; 422 for bad km bounds or run ids."""
        return _sel(db, self.line_id, self.track, self.run_ids, self.km_from, self.km_to)


def _runs_query(line_id: LineQ = None, track: TrackQ = None, run_ids: RunIdsQ = None,
                km_from: KmFromQ = None, km_to: KmToQ = None, wheel: WheelQ = None) -> _Runs:
    return _Runs(line_id, track, run_ids, km_from, km_to, wheel)


RunsQuery = Annotated[_Runs, Depends(_runs_query)]


def _lag(sel) -> int:
    return int(round(100.0 / sel.bin_length))


def _subsidence_pairs(df: pd.DataFrame, sub: pd.DataFrame, wheel: str, bin_length: float):
    """(amplitude, subsidence, run group, mask of the wheel's rows) of bins of ``wheel`` with a
    subsidence value of its rail."""
    pw = df[df["wheel"] == wheel]
    if sub.empty or pw.empty:
        return np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(len(pw), dtype=bool)
    rail = sub["rail"].to_numpy(dtype=np.float64, na_value=np.nan)
    side = int(wheel[1])
    own = sub[rail == side]
    use = own if len(own) else sub[~np.isfinite(rail)]
    sb, sv = bin_means(use["km"].to_numpy() * 1000, use["subsidence_mm"].to_numpy(), bin_length)
    bins = pw["bin"].to_numpy()
    m = np.isin(bins, sb)
    return (pw["sleeper_amp"].to_numpy()[m], sv[np.searchsorted(sb, bins[m])],
            pw["run_id"].to_numpy()[m], m)


def _subsidence_wheel(wheel, amp, u, groups, lag, confidence=0.95, max_points=_MAX_POINTS):
    f = fit_subsidence(amp, u, groups=groups, hac_lag=lag, confidence=confidence) if amp.size else None
    idx = decimate_indices(amp.size, max_points)
    return {
        "wheel": wheel,
        "slope": data.num(f.slope) if f else None, "slope_ci": data.nums(f.slope_ci) if f else [None, None],
        "intercept": data.num(f.intercept) if f else None,
        "intercept_ci": data.nums(f.intercept_ci) if f else [None, None],
        "rmse": data.num(f.rmse) if f else None, "n_samples": int(amp.size),
        "r2": data.num(f.r2) if f else None,
        "points": {"amplitude": amp[idx].tolist(), "subsidence_mm": u[idx].tolist()},
    }


@router.get("/analytics/subsidence-fit", response_model=SubsidenceFitOut,
            summary="Subsidence model u = a ln(Z) + b per wheel")
def subsidence_fit(db: DbDep, settings: SettingsDep, runs: RunsQuery,
                   confidence: Annotated[float, Query(gt=0.5, lt=1)] = 0.95,
                   normalise: Annotated[bool, Query(
                       description="fit on the amplitude normalised to reference_speed_kmh")] = False,
                   reference_speed_kmh: RefSpeedQ = None, max_points: PointsQ = _MAX_POINTS) -> dict:
    """Fit u (mm) = slope · ln(Z / 1 m/s²) + intercept on 25 cm bins with both a
    sleeper-passage amplitude Z (the wheel's own: its rail's subsidence, :func:`analytics_data.own_amplitude`)
    and a subsidence value of the wheel's rail (or of both rails). Intervals: ``confidence`` (default 95 %), Newey–West over 100 m.
    With ``normalise`` Z is the speed-normalised amplitude (runs of different speeds pool)."""
    sel = runs.select(db)
    w = _wheel(runs.wheel)
    df = data.own_amplitude(data.load_profiles(db, settings, sel, km_from=runs.km_from, km_to=runs.km_to, wheel=w))
    if normalise and not df.empty:
        ref_v = reference_speed_kmh or settings.analytics_reference_speed_kmh
        min_v = settings.analytics_min_speed_kmh
        _, fits = _norm_context(db, settings, sel, df, ref_v, min_v)
        namp, _ = data.normalised(df, data.reference(db, "superstructure", sel), fits, sel.bin_length,
                                  ref_v, min_v)
        df = df.assign(sleeper_amp=namp)
        df = df[np.isfinite(df["sleeper_amp"].to_numpy())]
    sub = data.reference(db, "subsidence", sel, km_from=runs.km_from, km_to=runs.km_to)
    wheels = []
    for wh in ([w] if w else sorted(df["wheel"].unique().tolist())):
        amp, u, g, _ = _subsidence_pairs(df, sub, wh, sel.bin_length)
        wheels.append(_subsidence_wheel(wh, amp, u, g, _lag(sel), confidence, max_points))
    return {"log_base": LOG_BASE, "run_ids": sel.run_ids, "wheels": wheels}


@router.get("/runs/{run_id}/predicted-subsidence", response_model=PredictedSubsidenceOut,
            summary="Subsidence predicted from a run's amplitude")
def predicted_subsidence(run_id: RunId, db: DbDep, settings: SettingsDep,
                         wheel: Annotated[str, Query(description="wheel")] = "12",
                         km_from: KmFromQ = None, km_to: KmToQ = None,
                         fit_run_ids: RunIdsQ = None) -> dict:
    """u = a ln(Z) + b with a, b fitted per wheel over ``fit_run_ids`` (default all runs of
    the run's line/track with results) on the whole line; ``measured_mm`` where measured."""
    check_km(km_from, km_to)
    w = _wheel(wheel)
    with db.read() as session:
        run, _ = run_with_results(session, run_id)
    fit_sel = data.select_runs(db, run.line_id, run.track, data.parse_run_ids(fit_run_ids)) \
        if (fit_run_ids or run.line_id is not None) else data.select_runs(db, None, None, [run_id])
    fdf = data.own_amplitude(data.load_profiles(db, settings, fit_sel, wheel=w))
    sub = data.reference(db, "subsidence", fit_sel)
    amp, u, g, _ = _subsidence_pairs(fdf, sub, w, fit_sel.bin_length)
    model = _subsidence_wheel(w, amp, u, g, _lag(fit_sel)) if amp.size >= 3 else None
    one = data.Selection(run.line_id, run.track, [run], fit_sel.bin_length)
    df = data.own_amplitude(data.load_profiles(db, settings, one, km_from=km_from, km_to=km_to, wheel=w))
    z = df["sleeper_amp"].to_numpy()
    pred = predict_subsidence(z, model["slope"], model["intercept"]) if model and model["slope"] is not None \
        else np.full(z.size, np.nan)
    measured = np.full(z.size, np.nan)
    if not sub.empty and z.size:
        _, u2, _, has = _subsidence_pairs(df, sub, w, fit_sel.bin_length)  # df holds wheel w only
        measured[has] = u2
    if model is not None:
        model["points"] = {"amplitude": [], "subsidence_mm": []}
    return {"run_id": run_id, "wheel": w, "log_base": LOG_BASE, "model": model,
            "fit_run_ids": fit_sel.run_ids, "km": df["km"].tolist(), "amplitude": data.nums(z),
            "subsidence_mm": data.nums(pred), "measured_mm": data.nums(measured)}


@router.get("/analytics/unsprung-mass", response_model=UnsprungMassOut,
            summary="Unsprung mass from force vs acceleration amplitude per wheel")
def unsprung_mass(db: DbDep, settings: SettingsDep, runs: RunsQuery,
                  mass_min_kg: Annotated[float, Query(ge=0)] = 150.0,
                  mass_max_kg: Annotated[float, Query(gt=0)] = 600.0,
                  max_points: PointsQ = _MAX_POINTS) -> dict:
    """Slope of the sleeper-passage force amplitude (kN) on the acceleration amplitude
    (m/s²) × 1000 = mass (kg); outside [mass_min_kg, mass_max_kg] → ``plausible: false``.

    Both amplitudes of the same wheel as measured (:func:`analytics_data.own_amplitude`): the roughness
    response is in both, so it is not taken out of either."""
    if mass_min_kg >= mass_max_kg:
        raise ApiError(422, "mass_min_kg", "must be below mass_max_kg")
    sel = runs.select(db)
    w = _wheel(runs.wheel)
    df = data.own_amplitude(data.load_profiles(db, settings, sel, km_from=runs.km_from, km_to=runs.km_to, wheel=w))
    df = df[np.isfinite(df["sleeper_force_amp"].to_numpy(dtype=np.float64))]
    out = []
    for wh in ([w] if w else sorted(df["wheel"].unique().tolist())):
        pw = df[df["wheel"] == wh]
        z, f = pw["sleeper_amp"].to_numpy(), pw["sleeper_force_amp"].to_numpy()
        mf = fit_unsprung_mass(z, f, groups=pw["run_id"].to_numpy(), hac_lag=_lag(sel),
                               plausible_kg=(mass_min_kg, mass_max_kg)) if z.size else None
        idx = decimate_indices(z.size, max_points)
        out.append({"wheel": wh, "mass_kg": data.num(mf.mass_kg) if mf else None,
                    "mass_ci": data.nums(mf.mass_ci) if mf else [None, None],
                    "r2": data.num(mf.fit.r2) if mf else None, "n_samples": int(z.size),
                    "plausible": bool(mf.plausible) if mf else False,
                    "points": {"acceleration": z[idx].tolist(), "force_kn": f[idx].tolist()}})
    return {"plausible_range_kg": [mass_min_kg, mass_max_kg], "run_ids": sel.run_ids, "wheels": out}


@router.get("/analytics/maintenance", response_model=MaintenanceOut,
            summary="Amplitude against the number of maintenance actions per bin")
def maintenance(db: DbDep, settings: SettingsDep, runs: RunsQuery,
                type: Annotated[str | None, Query(description="comma-separated types (default all)")] = None,
                since: Annotated[dt.date | None, Query(description="actions on or after")] = None) -> dict:
    """Per 25 cm bin: the mean amplitude over the runs (and wheels) and the number of
    actions covering it; box plots per count and the regression amplitude = slope · n + intercept
    (p-value: Newey–West over 100 m)."""
    sel = runs.select(db)
    types = parse_types(type)
    df = data.load_profiles(db, settings, sel, km_from=runs.km_from, km_to=runs.km_to, wheel=_wheel(runs.wheel))
    acts = data.reference(db, "maintenance", sel, km_from=runs.km_from, km_to=runs.km_to, types=types, since=since)
    empty = {"types": types or [], "since": since.isoformat() if since else None, "run_ids": sel.run_ids,
             "groups": [], "regression": {"slope": None, "intercept": None, "r": None, "p_value": None, "n": 0}}
    if acts.empty or df.empty:
        return empty
    pb = df.groupby("bin", sort=True)["sleeper_amp"].mean()
    pos = (pb.index.to_numpy() + 0.5) * sel.bin_length
    counts = count_actions(pos, acts["km_from"].to_numpy() * 1000, acts["km_to"].to_numpy() * 1000)
    res = maintenance_correlation(pb.to_numpy(), counts, hac_lag=_lag(sel))
    f = res.regression
    return {**empty, "groups": res.groups,
            "regression": {"slope": data.num(f.slope), "intercept": data.num(f.intercept), "r": data.num(f.r),
                           "p_value": data.num(f.p_value), "n": int(f.n)}}


def _norm_context(db, settings, sel, df, ref_speed, min_speed):
    sections = data.reference(db, "superstructure", sel)
    fits = data.speed_exponents(df, sections, sel.bin_length, ref_speed, min_speed)
    return sections, fits


@router.get("/analytics/superstructure", response_model=SuperstructureOut,
            summary="Amplitude per superstructure type and outlying segments")
def superstructure(db: DbDep, settings: SettingsDep, runs: RunsQuery,
                   segment_m: Annotated[float, Query(gt=0, le=10_000)] = 100.0,
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
    sel = runs.select(db)
    ref_v = reference_speed_kmh or settings.analytics_reference_speed_kmh
    min_v = settings.analytics_min_speed_kmh if min_speed_kmh is None else min_speed_kmh
    df = data.load_profiles(db, settings, sel, km_from=runs.km_from, km_to=runs.km_to, wheel=_wheel(runs.wheel),
                            min_speed_kmh=min_v)
    sections = data.reference(db, "superstructure", sel)
    out = {"normalised": False, "conditioning": None, "reference_speed_kmh": ref_v, "run_ids": sel.run_ids,
           "types": [], "segments": [], "flagged": []}
    if sections.empty or df.empty:
        return out
    amp = df["sleeper_amp"].to_numpy()
    if normalise:
        if conditioning == "power_law":
            fits = data.speed_exponents(df, sections, sel.bin_length, ref_v, min_v)
            namp, _ = data.normalised(df, sections, fits, sel.bin_length, ref_v, min_v)
        else:
            ctx = index_context(db, settings, sel.line_id, sel.track, sel.bin_length)
            namp = ctx.at_reference_speed(df, ref_v / 3.6)
        if np.isfinite(namp).any():
            amp, out["normalised"], out["conditioning"] = namp, True, conditioning
    df = df.assign(value=amp)
    df = df[np.isfinite(df["value"].to_numpy())]
    pb = df.groupby("bin", sort=True)["value"].mean()
    pos = (pb.index.to_numpy() + 0.5) * sel.bin_length
    idx, types = data.section_types(sections, pos)
    inside = idx >= 0
    out["types"] = type_distributions(pb.to_numpy()[inside], types[inside])
    flags = flag_segments(pos, pb.to_numpy(), idx, list(sections["type"]), segment_m=segment_m,
                          bin_length_m=sel.bin_length, z_threshold=z_threshold)
    ids = sections["id"].to_numpy()
    segs = [{"section_id": int(ids[f.section]), "type": f.type, "km_from": f.start_m / 1000,
             "km_to": f.end_m / 1000, "n_bins": f.n_bins, "median": f.median, "z": data.num(f.z),
             "flagged": f.flagged} for f in flags]
    out["segments"], out["flagged"] = segs, [s for s in segs if s["flagged"]]
    return out


@router.get("/analytics/speed-normalisation", response_model=SpeedNormOut,
            summary="Speed exponent of the amplitude per superstructure type")
def speed_normalisation(db: DbDep, settings: SettingsDep, runs: RunsQuery,
                        reference_speed_kmh: RefSpeedQ = None,
                        min_speed_kmh: MinSpeedQ = None) -> dict:
    """ln A = exponent · ln(v / v_ref) + c per type ('*' = all bins, '' = outside any
    section), estimated within bins passed at several speeds where possible. An explicit
    option (the default speed conditioning is the stiffness index): every exponent comes with
    ``stable`` and the reasons it should not be trusted."""
    sel = runs.select(db)
    ref_v = reference_speed_kmh or settings.analytics_reference_speed_kmh
    min_v = settings.analytics_min_speed_kmh if min_speed_kmh is None else min_speed_kmh
    df = data.load_profiles(db, settings, sel, km_from=runs.km_from, km_to=runs.km_to, wheel=_wheel(runs.wheel),
                            min_speed_kmh=min_v)
    _, fits = _norm_context(db, settings, sel, df, ref_v, min_v)
    stored = curves_db.current_reference(db, sel.line_id, sel.track, curves_db.CurveParams.from_settings(settings)) \
        if sel.line_id is not None and fits else None
    misfit = curve_misfits(stored, {t: f.exponent for t, f in fits.items() if t != "*"})
    types = []
    for t, f in fits.items():
        if misfit.get(t, 0.0) > MAX_POWER_LAW_MISFIT:
            f = f.with_reason("not_power_law")
        types.append({"type": t, "exponent": data.num(f.exponent), "exponent_ci": data.nums(f.exponent_ci),
                      "method": f.method, "n_samples": f.n_samples, "amplitude_at_ref": data.num(f.amplitude_at_ref),
                      "stable": f.stable, "unstable_reasons": list(f.unstable_reasons),
                      "log_speed_std": data.num(f.log_speed_std), "power_law_misfit": data.num(misfit.get(t)),
                      "plausible": f.plausible, "warning": f.warning})
    return {"reference_speed_kmh": ref_v, "min_speed_kmh": min_v, "run_ids": sel.run_ids, "types": types}


@router.get("/runs/{run_id}/speed-normalised-profile", response_model=NormalisedProfileOut,
            summary="A run's amplitude normalised to a reference speed")
def speed_normalised_profile(run_id: RunId, db: DbDep, settings: SettingsDep,
                             wheel: Annotated[str, Query()] = "12", km_from: KmFromQ = None,
                             km_to: KmToQ = None, reference_speed_kmh: RefSpeedQ = None,
                             min_speed_kmh: MinSpeedQ = None, fit_run_ids: RunIdsQ = None) -> dict:
    """A · (v_ref / v) ** exponent per bin, the exponent of the bin's superstructure type
    fitted over ``fit_run_ids`` (default all runs of the line/track); null below the minimum speed."""
    check_km(km_from, km_to)
    w = _wheel(wheel)
    with db.read() as session:
        run, _ = run_with_results(session, run_id)
    ref_v = reference_speed_kmh or settings.analytics_reference_speed_kmh
    min_v = settings.analytics_min_speed_kmh if min_speed_kmh is None else min_speed_kmh
    ids = data.parse_run_ids(fit_run_ids)
    fit_sel = data.select_runs(db, run.line_id, run.track, ids) if (ids or run.line_id) else \
        data.select_runs(db, None, None, [run_id])
    fdf = data.load_profiles(db, settings, fit_sel, wheel=w, min_speed_kmh=min_v)
    sections, fits = _norm_context(db, settings, fit_sel, fdf, ref_v, min_v)
    one = data.Selection(run.line_id, run.track, [run], fit_sel.bin_length)
    df = data.load_profiles(db, settings, one, km_from=km_from, km_to=km_to, wheel=w, min_speed_kmh=0.0)
    if fits:
        namp, types = data.normalised(df, sections, fits, fit_sel.bin_length, ref_v, min_v)
    else:
        namp, types = np.full(len(df), np.nan), np.full(len(df), "", dtype=object)
    return {"run_id": run_id, "wheel": w, "reference_speed_kmh": ref_v, "min_speed_kmh": min_v,
            "exponents": {t: data.num(f.exponent) for t, f in fits.items()},
            "km": df["km"].tolist(), "speed_kmh": data.nums(df["speed_mean"].to_numpy() * 3.6),
            "type": [t or None for t in types], "amplitude": data.nums(df["sleeper_amp"].to_numpy()),
            "amplitude_normalised": data.nums(namp)}


def _alignment(sel, df, run_id, ref_id, max_shift_m, detrend_m):
    """The alignment of a run to the reference run, for every endpoint that reports one.

    A run aligned to itself is the identity: shift 0 and confidence 1 (nothing is estimated;
    its correlation curve is still returned)."""
    a = df[df["run_id"] == ref_id].groupby("bin")["sleeper_amp"].mean()
    b = df[df["run_id"] == run_id].groupby("bin")["sleeper_amp"].mean()
    if a.empty or b.empty:
        return None
    al = align_runs(a.index.to_numpy(), a.to_numpy(), b.index.to_numpy(), b.to_numpy(),
                    bin_length_m=sel.bin_length, max_shift_m=max_shift_m, detrend_m=detrend_m)
    if run_id == ref_id:
        al = dataclasses.replace(al, shift_m=0.0, confidence=1.0)
    return al


MaxShiftQ = Annotated[float, Query(gt=0, le=5000, description="largest shift searched, m")]


@router.get("/runs/{run_id}/alignment", response_model=AlignmentOut,
            summary="km shift of a run against a reference run")
def run_alignment(run_id: RunId, db: DbDep, settings: SettingsDep,
                  reference_run_id: Annotated[int | None, Query(ge=1)] = None,
                  max_shift_m: MaxShiftQ = 50.0,
                  detrend_m: Annotated[float, Query(gt=0, le=10_000)] = 50.0) -> dict:
    """Cross-correlate the run's amplitude signature (mean over wheels) with the reference
    run's (default: the earliest run of the same line/track with results)."""
    with db.read() as session:
        run = crud.get_run(session, run_id)
        if run is None:
            raise not_found("run", run_id)
    if reference_run_id is None:
        sel = data.select_runs(db, run.line_id, run.track, None) if run.line_id else \
            data.select_runs(db, None, None, [run_id])
        if run_id not in sel.run_ids:
            raise ApiError(409, "profile", f"run {run_id} has no results yet")
        reference_run_id = sel.run_ids[0]
    sel = data.select_runs(db, None, None, sorted({run_id, reference_run_id}))
    df = data.load_profiles(db, settings, sel)
    al = _alignment(sel, df, run_id, reference_run_id, max_shift_m, detrend_m)
    if al is None:
        raise ApiError(409, "profile", "no amplitude to align (runs too short or too slow)")
    return {"run_id": run_id, "reference_run_id": reference_run_id, "shift_m": data.num(al.shift_m),
            "shift_confidence": al.confidence, "peak_r": data.num(al.peak_r), "second_r": data.num(al.second_r),
            "overlap_m": al.overlap_m, "lags_m": al.lags_m.tolist(), "correlation": data.nums(al.correlation)}


ValueQ = Annotated[Literal["amplitude", "index"], Query(
    description="amplitude: mean sleeper-passage amplitude (m/s²); index: mean stiffness index (ln units)")]


def _segments(db, settings, sel, km_from, km_to, wheel, segment_m, align, max_shift_m, value="amplitude"):
    df = data.load_profiles(db, settings, sel, km_from=km_from, km_to=km_to, wheel=wheel)
    column = "sleeper_amp"
    if value == "index":
        df = index_context(db, settings, sel.line_id, sel.track, sel.bin_length).add_columns(df)
        column = "stiffness_index"
    runs, shifts, info, speeds = [], [], [], []
    ref_id = sel.run_ids[0] if sel.runs else None
    for run in sel.runs:
        per_bin = df[df["run_id"] == run.id].groupby("bin")
        g = per_bin["sleeper_amp"].mean()
        shift, conf = 0.0, None
        if align and len(g):
            al = _alignment(sel, df, run.id, ref_id, max_shift_m, 50.0)
            if al is not None and np.isfinite(al.shift_m):
                shift, conf = al.shift_m, al.confidence
        runs.append((g.index.to_numpy(), per_bin[column].mean().to_numpy()))
        speeds.append(per_bin["speed_mean"].mean().to_numpy())
        shifts.append(shift)
        info.append({"run_id": run.id, "start_time": run.start_time.isoformat() if run.start_time else None,
                     "shift_m": shift if align else None, "shift_confidence": conf if align else None})
    table = segment_table(runs, shifts, bin_length_m=sel.bin_length, segment_m=segment_m, speeds=speeds,
                          speed_tolerance=settings.analytics_speed_tolerance)
    return ref_id, info, table


@router.get("/analytics/segments", response_model=SegmentsOut,
            summary="Per-segment mean amplitude per run, mean, spread and change over runs")
def segments(db: DbDep, settings: SettingsDep, runs: RunsQuery,
             segment_m: Annotated[float, Query(gt=0, le=10_000)] = 100.0,
             align: bool = True, max_shift_m: MaxShiftQ = 50.0, value: ValueQ = "amplitude") -> dict:
    """Runs (by start time) are aligned to the first one (``align``), then averaged per
    segment; ``spread`` is the standard deviation over runs, ``change`` last minus first
    where the two passed at matched speed (``TRACKVKF_ANALYTICS_SPEED_TOLERANCE``; else null)."""
    sel = runs.select(db)
    ref_id, info, t = _segments(db, settings, sel, runs.km_from, runs.km_to, _wheel(runs.wheel), segment_m, align,
                                max_shift_m, value)
    return {"segment_m": segment_m, "value": value, "reference_run_id": ref_id, "km": (t.start_m / 1000).tolist(),
            "runs": info, "matrix": [data.nums(row) for row in t.matrix], "mean": data.nums(t.mean),
            "spread": data.nums(t.spread), "change": data.nums(t.change),
            "speed_kmh": [data.nums(row * 3.6) for row in t.speed],
            "speed_tolerance": settings.analytics_speed_tolerance}


@router.get("/analytics/segment-trend", response_model=SegmentTrendOut,
            summary="Amplitude of one segment over runs (dates)")
def segment_trend(db: DbDep, settings: SettingsDep, km: Annotated[float, km_query()],
                  line_id: LineQ = None, track: TrackQ = None, run_ids: RunIdsQ = None, wheel: WheelQ = None,
                  segment_m: Annotated[float, Query(gt=0, le=10_000)] = 100.0, align: bool = True,
                  max_shift_m: MaxShiftQ = 50.0, value: ValueQ = "amplitude") -> dict:
    """The mean amplitude (or stiffness index) of the segment holding ``km`` in each run, by start
    time, with the run's mean speed there."""
    sel = _sel(db, line_id, track, run_ids, None, None)
    w = _wheel(wheel)
    start = np.floor(km * 1000 / segment_m) * segment_m
    lo, hi = (start - max_shift_m - 200) / 1000, (start + segment_m + max_shift_m + 200) / 1000
    _, info, t = _segments(db, settings, sel, lo, hi, w, segment_m, align, max_shift_m, value)
    j = np.flatnonzero(np.isclose(t.start_m, start))
    points = [{"run_id": r["run_id"], "start_time": r["start_time"],
               value: data.num(t.matrix[i, j[0]]) if j.size else None,
               "speed_kmh": data.num(t.speed[i, j[0]] * 3.6) if j.size else None} for i, r in enumerate(info)]
    return {"km": km, "segment_km": [start / 1000, (start + segment_m) / 1000], "wheel": w, "value": value,
            "points": points}
