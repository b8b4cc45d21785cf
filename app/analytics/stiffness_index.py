"""The stiffness index of stored rows and the answers about its reference curves.

The index ``ln(A / A_ref(class, v))`` (:func:`app.analysis.stiffness.stiffness_index.stiffness_index`)
against the line's current reference curves (computed from all its runs, cached in SQL
and refreshed when stale: :mod:`app.analytics.reference_curves`) is a column of the
profile answers and exports (``index=true``), computed row by row here
(:class:`IndexContext`). :func:`reference_curves_answer` is what
``GET /analytics/reference-curves`` (and its ``refresh``) answer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from app.analysis.stiffness.speed_norm import power_law_misfit
from app.analysis.units import KMH_PER_MPS
from app.analytics import reference_curves as curves_db
from app.analytics.frames import select_runs
from app.core.errors import ApiError
from app.core.i18n import _
from app.core.jsonable import finite_list, finite_or_none
from app.db.session import Database
from app.settings import Settings

__all__ = ["INDEX_COLUMNS", "IndexContext", "index_context", "curve_misfits", "reference_curves_answer"]

#: Columns the profile answers and exports add with ``index=true``.
INDEX_COLUMNS: tuple[str, ...] = ("stiffness_index", "stiffness_index_se", "reference_amp")


@dataclass(frozen=True)
class IndexContext:
    """What the index of one run's rows needs: the line's curves and sections, or why there are none."""

    stored: curves_db.StoredReference | None
    sections: pd.DataFrame
    bin_length: float
    reason: str | None

    def add_columns(self, df: pd.DataFrame) -> pd.DataFrame:
        """``df`` (rows with ``bin, sleeper_amp, speed_mean``) with :data:`INDEX_COLUMNS` added."""
        out = df.copy()
        if self.stored is None or df.empty:
            for c in INDEX_COLUMNS:
                out[c] = np.nan
            return out
        res = curves_db.index_of_rows(self.stored, self.sections, df["bin"].to_numpy(),
                                      df["sleeper_amp"].to_numpy(dtype=np.float64),
                                      df["speed_mean"].to_numpy(dtype=np.float64), self.bin_length)
        out["stiffness_index"] = res.index
        out["stiffness_index_se"] = res.se
        out["reference_amp"] = np.where(np.isfinite(res.index), res.reference_amp, np.nan)
        return out

    def at_reference_speed(self, df: pd.DataFrame, reference_speed_mps: float) -> np.ndarray:
        """``A_ref(class, v_ref) · exp(index)`` per row: the amplitude the location would show at
        ``v_ref`` by its class's reference curve (NaN where either is undefined), m/s²."""
        if self.stored is None or df.empty:
            return np.full(len(df), np.nan)
        idx = self.add_columns(df)["stiffness_index"].to_numpy()
        pos = (df["bin"].to_numpy(dtype=np.float64) + 0.5) * self.bin_length
        cls = curves_db.classes_at(self.sections, pos, self.stored.params.section_margin_m)
        at_ref = np.full(len(df), np.nan)
        for c, curve in self.stored.reference.curves.items():
            m = np.array([x == c for x in cls.tolist()], dtype=bool)
            if m.any():
                at_ref[m] = np.exp(curve.evaluate(np.array([reference_speed_mps]))[0][0])
        return at_ref * np.exp(idx)

    def version(self) -> str:
        """What the index columns depend on besides the run's job: the curves' fingerprint (or why none)."""
        return self.stored.fingerprint if self.stored is not None else f"none: {self.reason}"

    def describe(self) -> dict:
        """The reference used (line, runs, classes and speed ranges), or why there is none."""
        if self.stored is None:
            return {"available": False, "reason": self.reason}
        return {"available": True, **self.stored.describe()}


def index_context(db: Database, settings: Settings, line_id: str | None, track: str | None,
                  bin_length: float) -> IndexContext:
    """The current curves of a line and track (computed if missing or stale)."""
    if line_id is None:
        return IndexContext(None, pd.DataFrame(), bin_length, "the run has no line_id: no reference curve")
    params = curves_db.CurveParams.from_settings(settings)
    stored = curves_db.current_reference(db, line_id, track, params)
    with db.read() as session:
        sections = curves_db.line_sections(session, line_id, track)
    if stored is None or not stored.reference.curves:
        return IndexContext(None, sections, bin_length, "no reference curve for the line yet")
    return IndexContext(stored, sections, bin_length, None)


def curve_misfits(stored: curves_db.StoredReference | None, exponents: dict[str, float]) -> dict[str, float]:
    """Largest departure (ln units) of each class's reference curve from its fitted power law."""
    out: dict[str, float] = {}
    if stored is None:
        return out
    for cls, alpha in exponents.items():
        curve = stored.reference.curves.get(cls)
        if curve is not None and math.isfinite(alpha):
            out[cls] = power_law_misfit(curve.log_speed, curve.log_amp, alpha)
    return out


def _curve_body(stored: curves_db.StoredReference | None, line_id: str, track: str | None,
                settings: Settings) -> dict:
    params = curves_db.CurveParams.from_settings(settings)
    base = {"line_id": line_id, "track": track, "speed_tolerance": params.speed_tolerance,
            "section_margin_m": params.section_margin_m, "min_speed_kmh": params.min_speed_kmh,
            "pooling": "wheels pooled; wheel_offsets are diagnostics",
            "run_ids": [], "computed_at": None, "compute_s": None, "classes": [], "wheel_offsets": [],
            "rail_difference": None}
    if stored is None:
        return base
    ref = stored.reference
    classes = []
    for c, cu in ref.curves.items():
        lo, hi = cu.speed_range_mps
        ok = np.isfinite(cu.log_amp)
        classes.append({
            "class": c, "label": c or "line (no superstructure section)", "method": cu.method,
            "n_runs": cu.n_runs, "n_samples": cu.n_samples, "n_locations": cu.n_locations,
            "spread": finite_or_none(cu.spread), "repeatability": finite_or_none(cu.repeatability),
            "confidence": cu.confidence,
            "speed_range_kmh": [finite_or_none(lo * KMH_PER_MPS), finite_or_none(hi * KMH_PER_MPS)],
            "speed_kmh": finite_list(np.exp(cu.log_speed[ok]) * KMH_PER_MPS),
            "amplitude": finite_list(np.exp(cu.log_amp[ok])),
            "low": finite_list(np.exp(cu.log_amp_low[ok])), "high": finite_list(np.exp(cu.log_amp_high[ok])),
            "log_se": finite_list(cu.log_amp_se[ok]),
            "support": [int(s) for s in cu.support[ok]], "support_runs": [int(s) for s in cu.support_runs[ok]],
        })
    offsets = [{"wheel": o.wheel, "offset": finite_or_none(o.offset), "low": finite_or_none(o.low), "high": finite_or_none(o.high),
                "n_samples": o.n_samples} for o in ref.wheel_offsets]
    return {**base, "track": stored.track or track, "run_ids": stored.run_ids, "computed_at": stored.computed_at,
            "compute_s": stored.compute_s, "classes": classes, "wheel_offsets": offsets,
            "rail_difference": finite_or_none(ref.rail_difference)}


def _line(db: Database, line_id: str | None, track: str | None) -> tuple[str, str | None]:
    if line_id is None:
        raise ApiError(422, "line_id", _("is required"))
    sel = select_runs(db, line_id, track, None)
    return line_id, sel.track


def reference_curves_answer(db: Database, settings: Settings, line_id: str | None, track: str | None, *,
                            refresh: bool = False) -> dict:
    """The reference curves of a line and track with their provenance: the current ones (computed
    and cached when missing or stale), or recomputed now (``refresh``)."""
    line_id, track = _line(db, line_id, track)
    params = curves_db.CurveParams.from_settings(settings)
    stored = (curves_db.refresh_reference if refresh else curves_db.current_reference)(db, line_id, track, params)
    return _curve_body(stored, line_id, track, settings)
