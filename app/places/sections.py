"""Section classes of a line (EN 13848-6 / CEN TR 16513 style): per section (200 m by default) a
class A … E from the speed-conditioned stiffness index of the store's 10 m rows, for the newest
run and for the newest run at least a year before it, with the length per class.

The index is ``ln(A / A_ref(class, v))`` per 10 m segment, mean over the wheels, exactly as the
places use it (:func:`app.places.index.run_segment_rails`: the curves of the run's method-version
history; docs/places.md); the classes come from
:func:`app.analysis.condition.section_class.section_classes` with ``TRACKVKF_PLACES_SECTION_M`` and
``TRACKVKF_PLACES_SECTION_LIMITS``.
"""

from __future__ import annotations

import datetime as dt
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from app.analysis.condition.section_class import (
    DEFAULT_SECTION_LIMITS,
    SECTION_CLASSES,
    SectionClassLimits,
    section_classes,
)
from app.condition import readers as reader
from app.condition.lines import resolve_line
from app.core.csv_export import csv_text
from app.db.models import ConditionLine, ConditionRun
from app.db.session import Database
from app.places.class_scheme import class_scheme
from app.places.config import PlacesConfig
from app.places.index import SEGMENT_M, run_segment_rails

__all__ = ["SEGMENT_M", "CSV_COLUMNS", "line_sections", "section_limits", "sections_csv"]

_YEAR = dt.timedelta(days=365)


def _run_index(session: Session, line: ConditionLine, run: ConditionRun,
               config: PlacesConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The index of a run per 10 m segment (mean over wheels) exactly as the places use it, and the rails'
    scatter at each segment (:func:`app.places.index.run_segment_rails`)."""
    return run_segment_rails(session, line, run.run_id, config=config)


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def section_limits(settings: Any) -> SectionClassLimits:
    """``TRACKVKF_PLACES_SECTION_LIMITS`` (default :data:`~app.analysis.condition.section_class.DEFAULT_SECTION_LIMITS`)."""
    lim = getattr(settings, "places_section_limits", None)
    return SectionClassLimits(*lim) if lim else DEFAULT_SECTION_LIMITS


def line_sections(db: Database, settings: Any, line_id: str, track: str | None, *,
                  section_m: float | None = None, lang: str = "en") -> dict[str, Any]:
    """The section classes of a line's newest run, and the length per class now and a year before.

    Parameters
    ----------
    db : Database
    settings : Settings
        The places' settings (:meth:`app.places.config.PlacesConfig.from_settings`),
        ``places_section_m`` and ``places_section_limits``.
    line_id, track : str
        The store's line (404 naming ``line_id`` without runs, 422 naming ``track`` when ambiguous).
    section_m : float, optional
        Section length, m (a whole multiple of 10 m; default ``places_section_m``).
    lang : str
        Language of the class scheme's names.

    Returns
    -------
    dict
        ``section_m, limits, sections [{km_from, km_to, class, scheme_class, level, spread (the support's),
        rms, rail_spread (the rails' scatter from segment to segment taken out of the spread), fill}], length_by_class {A..E, "": m}, length_by_class_year_ago (or None), the same per
        class of the railway's scheme (``scheme``: :mod:`app.places.class_scheme`), run_id,
        run_time, run_id_year_ago, run_time_year_ago``.
    """
    line = resolve_line(db, line_id, track)
    limits = section_limits(settings)
    section_m = float(section_m if section_m is not None else settings.places_section_m)
    config = PlacesConfig.from_settings(settings)
    with db.read() as session:
        runs = reader.line_runs(session, line.id)
        k = len(runs) - 1
        segs, idx, rail = _run_index(session, line, runs[k], config)
        sc = section_classes(segs, idx, segment_m=SEGMENT_M, limits=limits, section_m=section_m, rail_scatter=rail)
        before = [i for i, r in enumerate(runs) if r.run_time <= runs[k].run_time - _YEAR]
        old = None
        if before:
            j = before[-1]
            osegs, oidx, orail = _run_index(session, line, runs[j], config)
            old = (runs[j], section_classes(osegs, oidx, segment_m=SEGMENT_M, limits=limits, section_m=section_m,
                                            rail_scatter=orail))
    per = int(round(section_m / SEGMENT_M))
    scheme = class_scheme(settings)
    sections = [
        {"km_from": float(sc.start_m[i]) / 1000.0, "km_to": float(sc.end_m[i]) / 1000.0, "class": str(sc.cls[i]),
         "scheme_class": scheme.code(str(sc.cls[i])),
         "level": _finite(sc.level[i]), "spread": _finite(sc.spread[i]), "rms": _finite(sc.rms[i]),
         "rail_spread": _finite(sc.rail_spread[i]) if sc.rail_spread is not None else None,
         "fill": float(sc.n_segments[i]) / per}
        for i in range(len(sc))
    ]
    return {
        "line_id": line.line_id, "track": line.track, "section_m": float(section_m),
        "limits": limits.limits.tolist(), "classes": list(SECTION_CLASSES),
        "quantity": "stiffness index ln(A/A_ref(class, v)), mean over the wheels",
        "sections": sections, "length_by_class": sc.length_by_class(),
        "length_by_class_year_ago": old[1].length_by_class() if old else None,
        "scheme": scheme.describe(lang),
        "length_by_scheme_class": scheme.lengths(sc.length_by_class()),
        "length_by_scheme_class_year_ago": scheme.lengths(old[1].length_by_class()) if old else None,
        "run_id": runs[k].run_id, "run_time": runs[k].run_time,
        "run_id_year_ago": old[0].run_id if old else None, "run_time_year_ago": old[0].run_time if old else None,
    }


#: The columns of the sections CSV (one row per section).
CSV_COLUMNS: tuple[str, ...] = ("line_id", "track", "km_from", "km_to", "class", "scheme_class", "scheme_class_name",
                                "level", "spread", "rms", "fill")


def sections_csv(answer: dict[str, Any], lang: str | None = None) -> str:
    """The sections of a :func:`line_sections` answer as CSV: one row per section with the
    internal class and the class of the railway's scheme (its code and name); the header is
    :data:`CSV_COLUMNS`, or given ``lang`` their labels and units in it."""
    names = {k["code"]: k["name"] for k in answer["scheme"]["classes"]}
    rows = [[answer["line_id"], answer["track"], f"{x['km_from']:.3f}", f"{x['km_to']:.3f}", x["class"],
             x["scheme_class"], names.get(x["scheme_class"], ""),
             *("" if x[k] is None else f"{x[k]:.4f}" for k in ("level", "spread", "rms")), f"{x['fill']:.2f}"]
            for x in answer["sections"]]
    return csv_text(CSV_COLUMNS, rows, lang)
