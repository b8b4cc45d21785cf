"""The correlations of the amplitude with reference data (paper, section 4): subsidence, unsprung
mass, maintenance. Each function answers one analytics endpoint from the selected runs' rows
(:mod:`app.analytics.frames`) and the line's reference data; the numbers come from
:mod:`app.analysis.stiffness`.

Amplitudes are the sleeper-passage acceleration amplitudes in m/s², the logarithm is natural.
Missing reference data give empty results, not errors.
"""

from __future__ import annotations

import datetime as dt

import numpy as np
import pandas as pd

from app.analysis.stiffness.maintenance import count_actions, maintenance_correlation
from app.analysis.stiffness.regression import decimate_indices
from app.analysis.stiffness.subsidence import (
    LOG_BASE,
    bin_means,
    fit_subsidence,
    predict_subsidence,
)
from app.analysis.stiffness.unsprung_mass import fit_unsprung_mass
from app.analytics import frames as data
from app.analytics.frames import RunsQuery, Selection, hac_lag
from app.analytics.speed import normalisation_fits
from app.core.jsonable import finite_list, finite_or_none
from app.db.session import Database
from app.runs.lookup import run_with_results
from app.settings import Settings

__all__ = ["MAX_POINTS", "subsidence_fit", "predicted_subsidence", "unsprung_mass", "maintenance"]

#: Most scatter points an answer returns per wheel (the fits use all samples).
MAX_POINTS = 5000


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


def _subsidence_wheel(wheel, amp, u, groups, lag, confidence=0.95, max_points=MAX_POINTS):
    f = fit_subsidence(amp, u, groups=groups, hac_lag=lag, confidence=confidence) if amp.size else None
    idx = decimate_indices(amp.size, max_points)
    return {
        "wheel": wheel,
        "slope": finite_or_none(f.slope) if f else None, "slope_ci": finite_list(f.slope_ci) if f else [None, None],
        "intercept": finite_or_none(f.intercept) if f else None,
        "intercept_ci": finite_list(f.intercept_ci) if f else [None, None],
        "rmse": finite_or_none(f.rmse) if f else None, "n_samples": int(amp.size),
        "r2": finite_or_none(f.r2) if f else None,
        "points": {"amplitude": amp[idx].tolist(), "subsidence_mm": u[idx].tolist()},
    }


def subsidence_fit(db: Database, settings: Settings, q: RunsQuery, *, confidence: float, normalise: bool,
                   reference_speed_kmh: float | None, max_points: int) -> dict:
    """u (mm) = slope · ln(Z / 1 m/s²) + intercept per wheel on 25 cm bins with both a
    sleeper-passage amplitude Z (the wheel's own, :func:`frames.own_amplitude`: its rail's
    subsidence) and a subsidence value of the wheel's rail (or of both rails); Newey–West
    intervals over 100 m. With ``normalise`` Z is the speed-normalised amplitude (runs of
    different speeds pool)."""
    sel = q.select(db)
    w = q.wheel
    df = data.own_amplitude(data.load_profiles(db, settings, sel, km_from=q.km_from, km_to=q.km_to, wheel=w))
    if normalise and not df.empty:
        ref_v = reference_speed_kmh or settings.analytics_reference_speed_kmh
        min_v = settings.analytics_min_speed_kmh
        sections, fits = normalisation_fits(db, sel, df, ref_v, min_v)
        namp, _ = data.normalised(df, sections, fits, sel.bin_length, ref_v, min_v)
        df = df.assign(sleeper_amp=namp)
        df = df[np.isfinite(df["sleeper_amp"].to_numpy())]
    sub = data.reference(db, "subsidence", sel, km_from=q.km_from, km_to=q.km_to)
    wheels = []
    for wh in ([w] if w else sorted(df["wheel"].unique().tolist())):
        amp, u, g, _ = _subsidence_pairs(df, sub, wh, sel.bin_length)
        wheels.append(_subsidence_wheel(wh, amp, u, g, hac_lag(sel), confidence, max_points))
    return {"log_base": LOG_BASE, "run_ids": sel.run_ids, "wheels": wheels}


def predicted_subsidence(db: Database, settings: Settings, run_id: int, *, wheel: str, km_from: float | None,
                         km_to: float | None, fit_run_ids: list[int] | None) -> dict:
    """u = a ln(Z) + b along a run, with a, b fitted per wheel over ``fit_run_ids`` (default all
    runs of the run's line/track with results) on the whole line; ``measured_mm`` where measured."""
    with db.read() as session:
        run, _ = run_with_results(session, run_id)
    fit_sel = data.select_runs(db, run.line_id, run.track, fit_run_ids) \
        if (fit_run_ids or run.line_id is not None) else data.select_runs(db, None, None, [run_id])
    fdf = data.own_amplitude(data.load_profiles(db, settings, fit_sel, wheel=wheel))
    sub = data.reference(db, "subsidence", fit_sel)
    amp, u, g, _ = _subsidence_pairs(fdf, sub, wheel, fit_sel.bin_length)
    model = _subsidence_wheel(wheel, amp, u, g, hac_lag(fit_sel)) if amp.size >= 3 else None
    one = Selection(run.line_id, run.track, [run], fit_sel.bin_length)
    df = data.own_amplitude(data.load_profiles(db, settings, one, km_from=km_from, km_to=km_to, wheel=wheel))
    z = df["sleeper_amp"].to_numpy()
    pred = predict_subsidence(z, model["slope"], model["intercept"]) if model and model["slope"] is not None \
        else np.full(z.size, np.nan)
    measured = np.full(z.size, np.nan)
    if not sub.empty and z.size:
        _, u2, _, has = _subsidence_pairs(df, sub, wheel, fit_sel.bin_length)  # df holds wheel w only
        measured[has] = u2
    if model is not None:
        model["points"] = {"amplitude": [], "subsidence_mm": []}
    return {"run_id": run_id, "wheel": wheel, "log_base": LOG_BASE, "model": model,
            "fit_run_ids": fit_sel.run_ids, "km": df["km"].tolist(), "amplitude": finite_list(z),
            "subsidence_mm": finite_list(pred), "measured_mm": finite_list(measured)}


def unsprung_mass(db: Database, settings: Settings, q: RunsQuery, *, mass_min_kg: float, mass_max_kg: float,
                  max_points: int) -> dict:
    """Slope of the sleeper-passage force amplitude (kN) on the acceleration amplitude
    (m/s²) × 1000 = mass (kg); outside [mass_min_kg, mass_max_kg] → ``plausible: false``.

    Both amplitudes of the same wheel as measured (:func:`frames.own_amplitude`): the roughness
    response is in both, so it is not taken out of either."""
    sel = q.select(db)
    w = q.wheel
    df = data.own_amplitude(data.load_profiles(db, settings, sel, km_from=q.km_from, km_to=q.km_to, wheel=w))
    df = df[np.isfinite(df["sleeper_force_amp"].to_numpy(dtype=np.float64))]
    out = []
    for wh in ([w] if w else sorted(df["wheel"].unique().tolist())):
        pw = df[df["wheel"] == wh]
        z, f = pw["sleeper_amp"].to_numpy(), pw["sleeper_force_amp"].to_numpy()
        mf = fit_unsprung_mass(z, f, groups=pw["run_id"].to_numpy(), hac_lag=hac_lag(sel),
                               plausible_kg=(mass_min_kg, mass_max_kg)) if z.size else None
        idx = decimate_indices(z.size, max_points)
        out.append({"wheel": wh, "mass_kg": finite_or_none(mf.mass_kg) if mf else None,
                    "mass_ci": finite_list(mf.mass_ci) if mf else [None, None],
                    "r2": finite_or_none(mf.fit.r2) if mf else None, "n_samples": int(z.size),
                    "plausible": bool(mf.plausible) if mf else False,
                    "points": {"acceleration": z[idx].tolist(), "force_kn": f[idx].tolist()}})
    return {"plausible_range_kg": [mass_min_kg, mass_max_kg], "run_ids": sel.run_ids, "wheels": out}


def maintenance(db: Database, settings: Settings, q: RunsQuery, *, types: list[str] | None,
                since: dt.date | None) -> dict:
    """Per 25 cm bin the mean amplitude over the runs (and wheels) and the number of actions
    covering it; box plots per count and the regression amplitude = slope · n + intercept
    (p-value: Newey–West over 100 m)."""
    sel = q.select(db)
    df = data.load_profiles(db, settings, sel, km_from=q.km_from, km_to=q.km_to, wheel=q.wheel)
    acts = data.reference(db, "maintenance", sel, km_from=q.km_from, km_to=q.km_to, types=types, since=since)
    empty = {"types": types or [], "since": since.isoformat() if since else None, "run_ids": sel.run_ids,
             "groups": [], "regression": {"slope": None, "intercept": None, "r": None, "p_value": None, "n": 0}}
    if acts.empty or df.empty:
        return empty
    pb = df.groupby("bin", sort=True)["sleeper_amp"].mean()
    pos = (pb.index.to_numpy() + 0.5) * sel.bin_length
    counts = count_actions(pos, acts["km_from"].to_numpy() * 1000, acts["km_to"].to_numpy() * 1000)
    res = maintenance_correlation(pb.to_numpy(), counts, hac_lag=hac_lag(sel))
    f = res.regression
    return {**empty, "groups": res.groups,
            "regression": {"slope": finite_or_none(f.slope), "intercept": finite_or_none(f.intercept),
                           "r": finite_or_none(f.r), "p_value": finite_or_none(f.p_value), "n": int(f.n)}}
