"""Track impacts of a run (dipped welds and joints found by the pipeline): the route
(:mod:`app.profiles.impacts`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from app.api.deps import DbDep, RunId
from app.api.schemas.impacts import TrackImpactList
from app.profiles.impacts import run_track_impacts

__all__ = ["router"]

router = APIRouter(tags=["profiles"])


@router.get("/runs/{run_id}/track-impacts", response_model=TrackImpactList, summary="Track impacts of a run")
def get_track_impacts(
    run_id: RunId,
    db: DbDep,
    km_from: Annotated[float | None, Query(ge=-1e5, le=1e5, description="From km")] = None,
    km_to: Annotated[float | None, Query(ge=-1e5, le=1e5, description="To km")] = None,
) -> TrackImpactList:
    """Isolated impacts fixed to the track (dipped welds, joints), ascending km: where, how deep (mm) and
    which wheels met them. The profile's ``track_impact_mm`` column holds them per wheel and bin; the
    sleeper-passage columns are bridged around each (docs/indicator.md)."""
    return TrackImpactList(**run_track_impacts(db, run_id, km_from, km_to))
