"""The reference curves of a line and track: computed from its runs, cached in SQL, kept current.

:func:`current_reference` is the one way to get the curves the stiffness index
uses: it returns the cached row when it is current and otherwise computes and
stores it (on demand); the worker calls :func:`refresh_reference` when a job of
the line is published and no other job of the line is queued or running, so
requests rarely pay for the computation (it reads every 25 cm row of every run
of the line: a history uploaded at once is fitted once, not once per run).

A cached row is current when its **fingerprint** equals the line's current one:
a hash of the result jobs of the line's runs, its superstructure sections and
the settings of the curves (:class:`CurveParams`). New results, a reprocessing
job, a deleted run, imported sections or other settings therefore make it stale.

Classes: the superstructure type of the section holding a bin; ``""`` for
bins outside any section (the whole line when none is imported); no class
within ``section_margin_m`` of a change of type (:func:`classes_at`).
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd
from sqlalchemy import delete, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE
from app.analysis.stiffness.reference_curve import ReferenceSet, fit_reference_from_rows
from app.analysis.stiffness.stiffness_index import StiffnessIndex, stiffness_index
from app.analysis.stiffness.superstructure import section_classes
from app.analysis.units import KMH_PER_MPS, MIN_SPEED_KMH
from app.analytics.frames import analytics_frame
from app.analytics.settings import EDGE_TRIM_M, SECTION_MARGIN_M
from app.core.jsonable import finite_or_none
from app.db import reference_crud, results_reader
from app.db.models import ReferenceCurveRow, utcnow
from app.db.session import Database
from app.settings import Settings

__all__ = [
    "CURVE_VERSION",
    "CurveParams",
    "StoredReference",
    "classes_at",
    "line_sections",
    "current_reference",
    "refresh_reference",
    "stored_reference",
    "index_of_rows",
]

#: Version of the curve computation; a new version makes every cached row stale.
CURVE_VERSION = 1


@dataclass(frozen=True)
class CurveParams:
    """Settings the curves depend on (from :class:`~app.settings.Settings`)."""

    speed_tolerance: float = DEFAULT_SPEED_TOLERANCE
    section_margin_m: float = SECTION_MARGIN_M
    min_speed_kmh: float = MIN_SPEED_KMH
    edge_trim_m: float = EDGE_TRIM_M

    @classmethod
    def from_settings(cls, settings: Settings) -> CurveParams:
        """The ``analytics_*`` settings."""
        return cls(settings.analytics_speed_tolerance, settings.analytics_section_margin_m,
                   settings.analytics_min_speed_kmh, settings.analytics_edge_trim_m)


@dataclass(frozen=True)
class StoredReference:
    """The curves of a line and track with where they come from."""

    line_id: str
    track: str
    reference: ReferenceSet
    run_ids: list[int]
    job_ids: list[int]
    fingerprint: str
    computed_at: str
    compute_s: float
    params: CurveParams

    def describe(self) -> dict:
        """What the curves are, for API answers: line, runs, classes with speed ranges."""
        classes = []
        for c, cu in self.reference.curves.items():
            lo, hi = cu.speed_range_mps
            classes.append({"class": c, "method": cu.method, "n_runs": cu.n_runs,
                            "speed_range_kmh": [None if v is None else v * KMH_PER_MPS
                                                for v in (finite_or_none(lo), finite_or_none(hi))]})
        return {"line_id": self.line_id, "track": self.track, "run_ids": self.run_ids,
                "computed_at": self.computed_at, "speed_tolerance": self.params.speed_tolerance,
                "classes": classes}


def _track_key(track: str | None) -> str:
    return "" if track is None else track


def line_sections(session: Session, line_id: str, track: str | None) -> pd.DataFrame:
    """The superstructure sections of a line and track (empty frame if none)."""
    return reference_crud.reference_frame(session, "superstructure", line_id=line_id, track=track)


def classes_at(sections: pd.DataFrame, position_m: np.ndarray, margin_m: float) -> np.ndarray:
    """Class per position (m on the km axis) from the line's sections (module docstring)."""
    if sections.empty:
        return np.full(np.shape(position_m), "", dtype=object)
    return section_classes(position_m, sections["km_from"].to_numpy() * 1000.0,
                           sections["km_to"].to_numpy() * 1000.0, sections["type"].to_numpy(dtype=object),
                           boundary_margin_m=margin_m)


def _fingerprint(session: Session, line_id: str, track: str | None, params: CurveParams) -> tuple[str, list, list]:
    runs = results_reader.runs_with_results(session, line_id, track)
    pairs = sorted(results_reader.result_jobs(session, runs))
    sec = line_sections(session, line_id, track)
    sections = [] if sec.empty else sorted(
        [int(i), float(a), float(b), str(t)] for i, a, b, t in
        zip(sec["id"], sec["km_from"], sec["km_to"], sec["type"], strict=True))
    doc = {"v": CURVE_VERSION, "jobs": pairs, "sections": sections, "params": params.__dict__}
    digest = hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()
    return digest, [p[0] for p in pairs], [p[1] for p in pairs]


def _from_row(row: ReferenceCurveRow, params: CurveParams) -> StoredReference:
    return StoredReference(row.line_id, row.track, ReferenceSet.from_dict(row.body), list(row.run_ids),
                           list(row.job_ids), row.fingerprint, row.computed_at.isoformat(), row.compute_s, params)


def stored_reference(session: Session, line_id: str, track: str | None,
                     params: CurveParams) -> tuple[StoredReference | None, bool]:
    """The cached curves of a line and track (None if none) and whether they are current."""
    row = session.scalar(select(ReferenceCurveRow).where(
        ReferenceCurveRow.line_id == line_id, ReferenceCurveRow.track == _track_key(track)))
    if row is None:
        return None, False
    fp, _, _ = _fingerprint(session, line_id, track, params)
    return _from_row(row, params), row.fingerprint == fp


def refresh_reference(db: Database, line_id: str, track: str | None, params: CurveParams) -> StoredReference | None:
    """Compute the curves of a line and track from all its runs and store them (replacing the old row).

    Returns None when the line has no run with results (the old row, if any, is deleted).
    """
    t0 = time.perf_counter()
    with db.read() as session:
        fp, run_ids, job_ids = _fingerprint(session, line_id, track, params)
        runs = results_reader.runs_with_results(session, line_id, track)
        bin_length = max((results_reader.bin_length_of(results_reader.results_job(session, r.id)) for r in runs),
                         default=0.25)
        df = analytics_frame(session, results_reader.result_jobs(session, runs), bin_length_m=bin_length,
                                           min_speed_kmh=params.min_speed_kmh, edge_trim_m=params.edge_trim_m,
                                           columns=("speed_mean", "sleeper_amp"))
        sections = line_sections(session, line_id, track)
    key = _track_key(track)
    if not runs:
        with db.write() as session:
            session.execute(delete(ReferenceCurveRow).where(ReferenceCurveRow.line_id == line_id,
                                                            ReferenceCurveRow.track == key))
        return None
    pos = (df["bin"].to_numpy(dtype=np.float64) + 0.5) * bin_length
    wheel = df["wheel"].astype(str).to_numpy(dtype=object)
    rail = np.array([w[-1:] for w in wheel], dtype=object)
    ref = fit_reference_from_rows(
        df["sleeper_amp"].to_numpy(), df["speed_mean"].to_numpy(), pos, df["run_id"].to_numpy(), wheel, rail,
        classes_at(sections, pos, params.section_margin_m), bin_length_m=bin_length,
        speed_tolerance=params.speed_tolerance,
    )
    elapsed = time.perf_counter() - t0
    row = {"line_id": line_id, "track": key, "fingerprint": fp, "run_ids": run_ids, "job_ids": job_ids,
           "body": ref.to_dict(), "computed_at": utcnow(), "compute_s": elapsed}
    try:
        with db.write() as session:
            session.execute(delete(ReferenceCurveRow).where(ReferenceCurveRow.line_id == line_id,
                                                            ReferenceCurveRow.track == key))
            session.add(ReferenceCurveRow(**row))
    except IntegrityError:  # another process stored the same line at the same moment: theirs stands
        pass
    with db.read() as session:
        stored, _ = stored_reference(session, line_id, track, params)
    return stored


def current_reference(db: Database, line_id: str, track: str | None, params: CurveParams) -> StoredReference | None:
    """The curves of a line and track, computed and stored first when missing or stale.

    None when the line has no run with results.
    """
    with db.read() as session:
        stored, current = stored_reference(session, line_id, track, params)
    if stored is not None and current:
        return stored
    return refresh_reference(db, line_id, track, params)


def index_of_rows(stored: StoredReference, sections: pd.DataFrame, bins: np.ndarray, amplitude: np.ndarray,
                  speed_mps: np.ndarray, bin_length_m: float) -> StiffnessIndex:
    """The stiffness index of profile rows (bin index, amplitude m/s², speed m/s) of the line."""
    pos = (np.asarray(bins, dtype=np.float64) + 0.5) * bin_length_m
    return stiffness_index(amplitude, speed_mps, classes_at(sections, pos, stored.params.section_margin_m),
                           stored.reference)
