"""Speed conditioning of the amplitude: per superstructure type, the distribution at a reference
speed (conditioned by the stiffness index's reference curves, or by a fitted power law as an
explicit option), the speed exponents with their trust, and one run's normalised profile.
Each function answers one analytics endpoint; the numbers come from :mod:`app.analysis.stiffness`.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from app.analysis.stiffness.speed_norm import MAX_POWER_LAW_MISFIT, SpeedFit
from app.analysis.stiffness.superstructure import flag_segments, type_distributions
from app.analysis.units import KMH_PER_MPS
from app.analytics import frames as data
from app.analytics import reference_curves as curves_db
from app.analytics.frames import RunsQuery, Selection
from app.analytics.stiffness_index import curve_misfits, index_context
from app.core.jsonable import finite_list, finite_or_none
from app.db.session import Database
from app.runs.lookup import run_with_results
from app.settings import Settings

__all__ = ["normalisation_fits", "superstructure", "speed_normalisation", "speed_normalised_profile"]


def normalisation_fits(db: Database, sel: Selection, df: pd.DataFrame, ref_speed_kmh: float,
                       min_speed_kmh: float) -> tuple[pd.DataFrame, dict[str, SpeedFit]]:
    """The line's superstructure sections and the speed exponent per type fitted on ``df``."""
    sections = data.reference(db, "superstructure", sel)
    fits = data.speed_exponents(df, sections, sel.bin_length, ref_speed_kmh, min_speed_kmh)
    return sections, fits


def superstructure(db: Database, settings: Settings, q: RunsQuery, *, segment_m: float, z_threshold: float,
                   normalise: bool, conditioning: str, reference_speed_kmh: float | None,
                   min_speed_kmh: float | None) -> dict:
    """Distribution of the amplitude per type (the paper's clusters); segments of ``segment_m``
    whose median departs from their type by more than ``z_threshold`` robust standard deviations
    are flagged. With ``normalise`` the amplitude is first conditioned to the reference speed
    (``conditioning``: ``index`` by the reference curves, ``power_law`` by fitted exponents)."""
    sel = q.select(db)
    ref_v = reference_speed_kmh or settings.analytics_reference_speed_kmh
    min_v = settings.analytics_min_speed_kmh if min_speed_kmh is None else min_speed_kmh
    df = data.load_profiles(db, settings, sel, km_from=q.km_from, km_to=q.km_to, wheel=q.wheel,
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
            namp = ctx.at_reference_speed(df, ref_v / KMH_PER_MPS)
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
             "km_to": f.end_m / 1000, "n_bins": f.n_bins, "median": f.median, "z": finite_or_none(f.z),
             "flagged": f.flagged} for f in flags]
    out["segments"], out["flagged"] = segs, [s for s in segs if s["flagged"]]
    return out


def speed_normalisation(db: Database, settings: Settings, q: RunsQuery, *, reference_speed_kmh: float | None,
                        min_speed_kmh: float | None) -> dict:
    """ln A = exponent · ln(v / v_ref) + c per type ('*' = all bins, '' = outside any section),
    estimated within bins passed at several speeds where possible; every exponent with ``stable``
    and the reasons it should not be trusted (a curve that is not a power law among them)."""
    sel = q.select(db)
    ref_v = reference_speed_kmh or settings.analytics_reference_speed_kmh
    min_v = settings.analytics_min_speed_kmh if min_speed_kmh is None else min_speed_kmh
    df = data.load_profiles(db, settings, sel, km_from=q.km_from, km_to=q.km_to, wheel=q.wheel,
                            min_speed_kmh=min_v)
    _, fits = normalisation_fits(db, sel, df, ref_v, min_v)
    stored = curves_db.current_reference(db, sel.line_id, sel.track, curves_db.CurveParams.from_settings(settings)) \
        if sel.line_id is not None and fits else None
    misfit = curve_misfits(stored, {t: f.exponent for t, f in fits.items() if t != "*"})
    types = []
    for t, f in fits.items():
        if misfit.get(t, 0.0) > MAX_POWER_LAW_MISFIT:
            f = f.with_reason("not_power_law")
        types.append({"type": t, "exponent": finite_or_none(f.exponent), "exponent_ci": finite_list(f.exponent_ci),
                      "method": f.method, "n_samples": f.n_samples,
                      "amplitude_at_ref": finite_or_none(f.amplitude_at_ref),
                      "stable": f.stable, "unstable_reasons": list(f.unstable_reasons),
                      "log_speed_std": finite_or_none(f.log_speed_std),
                      "power_law_misfit": finite_or_none(misfit.get(t)),
                      "plausible": f.plausible, "warning": f.warning})
    return {"reference_speed_kmh": ref_v, "min_speed_kmh": min_v, "run_ids": sel.run_ids, "types": types}


def speed_normalised_profile(db: Database, settings: Settings, run_id: int, *, wheel: str, km_from: float | None,
                             km_to: float | None, reference_speed_kmh: float | None, min_speed_kmh: float | None,
                             fit_run_ids: list[int] | None) -> dict:
    """A · (v_ref / v) ** exponent per bin of a run, the exponent of the bin's superstructure type
    fitted over ``fit_run_ids`` (default all runs of the line/track); null below the minimum speed."""
    with db.read() as session:
        run, _ = run_with_results(session, run_id)
    ref_v = reference_speed_kmh or settings.analytics_reference_speed_kmh
    min_v = settings.analytics_min_speed_kmh if min_speed_kmh is None else min_speed_kmh
    fit_sel = data.select_runs(db, run.line_id, run.track, fit_run_ids) if (fit_run_ids or run.line_id) else \
        data.select_runs(db, None, None, [run_id])
    fdf = data.load_profiles(db, settings, fit_sel, wheel=wheel, min_speed_kmh=min_v)
    sections, fits = normalisation_fits(db, fit_sel, fdf, ref_v, min_v)
    one = Selection(run.line_id, run.track, [run], fit_sel.bin_length)
    df = data.load_profiles(db, settings, one, km_from=km_from, km_to=km_to, wheel=wheel, min_speed_kmh=0.0)
    if fits:
        namp, types = data.normalised(df, sections, fits, fit_sel.bin_length, ref_v, min_v)
    else:
        namp, types = np.full(len(df), np.nan), np.full(len(df), "", dtype=object)
    return {"run_id": run_id, "wheel": wheel, "reference_speed_kmh": ref_v, "min_speed_kmh": min_v,
            "exponents": {t: finite_or_none(f.exponent) for t, f in fits.items()},
            "km": df["km"].tolist(), "speed_kmh": finite_list(df["speed_mean"].to_numpy() * KMH_PER_MPS),
            "type": [t or None for t in types], "amplitude": finite_list(df["sleeper_amp"].to_numpy()),
            "amplitude_normalised": finite_list(namp)}
