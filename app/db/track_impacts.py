"""Track impacts of a run: the profile rows that hold one, grouped into impacts.

The pipeline writes an isolated track impact (a dipped weld or joint,
:mod:`app.pipeline.impacts`) into ``profile_bins.track_impact_mm`` of the bin
holding it, for every wheel that passed there. :func:`run_track_impacts`
reads those rows of the job a run shows (a partial index holds just them)
and gives one entry per impact: its km, its depth (mean over the wheels, and
per rail side) and the wheels.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from sqlalchemy import select
from sqlalchemy.orm import Session

from app.db.models import ProfileBin
from app.db.results_reader import results_job_id

__all__ = ["TrackImpactRow", "run_track_impacts", "SAME_IMPACT_M"]

#: Rows of different wheels closer than this along the track are one impact, m.
SAME_IMPACT_M = 1.5


@dataclass
class TrackImpactRow:
    """One track impact of a run.

    Attributes
    ----------
    km : float
        Position (mean of the wheels' bins), km.
    depth_mm : float
        Estimated depth, mm (mean over the wheels).
    depth_by_side_mm : dict
        Mean depth per rail side (``"1"`` right, ``"2"`` left), mm.
    wheels : list of str
        Wheels whose profile holds it.
    """

    km: float
    depth_mm: float
    depth_by_side_mm: dict[str, float] = field(default_factory=dict)
    wheels: list[str] = field(default_factory=list)


def run_track_impacts(session: Session, run_id: int, km_from: float | None = None,
                      km_to: float | None = None) -> tuple[int | None, list[TrackImpactRow]]:
    """The track impacts of the results a run shows, ascending km.

    Parameters
    ----------
    run_id : int
    km_from, km_to : float, optional
        Only impacts within this km range.

    Returns
    -------
    (job_id, impacts)
        ``job_id`` None (and no impacts) when the run has no results.
    """
    job_id = results_job_id(session, run_id)
    if job_id is None:
        return None, []
    stmt = select(ProfileBin.wheel, ProfileBin.km, ProfileBin.track_impact_mm).where(
        ProfileBin.job_id == job_id, ProfileBin.track_impact_mm.is_not(None))
    if km_from is not None:
        stmt = stmt.where(ProfileBin.km >= km_from)
    if km_to is not None:
        stmt = stmt.where(ProfileBin.km <= km_to)
    rows = sorted(session.execute(stmt).all(), key=lambda r: r[1])
    out: list[TrackImpactRow] = []
    group: list[tuple[str, float, float]] = []

    def close() -> None:
        if not group:
            return
        sides: dict[str, list[float]] = {}
        for w, _, d in group:
            sides.setdefault(str(w)[-1], []).append(float(d))
        out.append(TrackImpactRow(
            km=sum(k for _, k, _ in group) / len(group),
            depth_mm=sum(d for _, _, d in group) / len(group),
            depth_by_side_mm={s: sum(v) / len(v) for s, v in sorted(sides.items())},
            wheels=sorted({str(w) for w, _, _ in group}),
        ))
        group.clear()

    for wheel, km, depth in rows:
        if group and (float(km) - group[-1][1]) * 1000.0 > SAME_IMPACT_M:
            close()
        group.append((str(wheel), float(km), float(depth)))
    close()
    return job_id, out
