"""A run's track impacts as the API answers them: the profile rows holding one, grouped into impacts.

Every wheel that passed a dipped weld or joint holds it in the ``track_impact_mm`` column of its
bin there (:mod:`app.pipeline.impacts`); the wheels' bins differ a little, so rows closer than
:data:`SAME_IMPACT_M` along the track are one impact, with its km (mean of the wheels' bins), its
depth (mean over the wheels, and per rail side) and the wheels.
"""

from __future__ import annotations

from typing import Any

from app.core.errors import not_found
from app.db import crud
from app.db.results_reader import results_job_id
from app.db.session import Database
from app.db.track_impacts import track_impact_bins

__all__ = ["run_track_impacts", "group_impacts", "SAME_IMPACT_M"]

#: Rows of different wheels closer than this along the track are one impact, m.
SAME_IMPACT_M = 1.5


def run_track_impacts(db: Database, run_id: int, km_from: float | None = None,
                      km_to: float | None = None) -> dict[str, Any]:
    """The track impacts of the results a run shows, ascending km, optionally within ``km_from`` …
    ``km_to`` (km); ``job_id`` None and no impacts when the run has no results; 404 without the run."""
    with db.read() as session:
        if crud.get_run(session, run_id) is None:
            raise not_found("run", run_id)
        job_id = results_job_id(session, run_id)
        rows = track_impact_bins(session, job_id, km_from, km_to) if job_id is not None else []
    return {"run_id": run_id, "job_id": job_id, "items": group_impacts(rows)}


def group_impacts(rows: list[tuple[str, float, float]]) -> list[dict[str, Any]]:
    """One impact per run of ``(wheel, km, depth_mm)`` rows (ascending km) closer than
    :data:`SAME_IMPACT_M` to the previous one: ``km``, ``depth_mm``, ``depth_by_side_mm`` (``"1"``
    right, ``"2"`` left: the wheel name's last digit) and ``wheels``."""
    out: list[dict[str, Any]] = []
    group: list[tuple[str, float, float]] = []

    def close() -> None:
        sides: dict[str, list[float]] = {}
        for w, _, d in group:
            sides.setdefault(w[-1], []).append(d)
        out.append({
            "km": sum(k for _, k, _ in group) / len(group),
            "depth_mm": sum(d for _, _, d in group) / len(group),
            "depth_by_side_mm": {s: sum(v) / len(v) for s, v in sorted(sides.items())},
            "wheels": sorted({w for w, _, _ in group}),
        })
        group.clear()

    for wheel, km, depth in rows:
        if group and (km - group[-1][1]) * 1000.0 > SAME_IMPACT_M:
            close()
        group.append((wheel, km, depth))
    if group:
        close()
    return out
