"""The profile rows of a job that hold a track impact.

The pipeline writes an isolated track impact (a dipped weld or joint,
:mod:`app.pipeline.impacts`) into ``profile_bins.track_impact_mm`` of the bin
holding it, for every wheel that passed there; a partial index holds just
those rows. :mod:`app.profiles.impacts` groups them into impacts.
"""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session

from app.db.models import ProfileBin

__all__ = ["track_impact_bins"]


def track_impact_bins(session: Session, job_id: int, km_from: float | None = None,
                      km_to: float | None = None) -> list[tuple[str, float, float]]:
    """(wheel, km, depth in mm) of every profile row of ``job_id`` holding a track impact, ascending km,
    optionally only within ``km_from`` … ``km_to`` (km)."""
    stmt = select(ProfileBin.wheel, ProfileBin.km, ProfileBin.track_impact_mm).where(
        ProfileBin.job_id == job_id, ProfileBin.track_impact_mm.is_not(None))
    if km_from is not None:
        stmt = stmt.where(ProfileBin.km >= km_from)
    if km_to is not None:
        stmt = stmt.where(ProfileBin.km <= km_to)
    rows = session.execute(stmt.order_by(ProfileBin.km, ProfileBin.wheel)).all()
    return [(str(w), float(k), float(d)) for w, k, d in rows]
