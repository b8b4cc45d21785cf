"""Wheel out-of-roundness results of a run."""

from __future__ import annotations

from fastapi import APIRouter

from app.api.deps import DbDep, RunId
from app.api.errors import ApiError, not_found
from app.api.schemas.wheels import WheelList, WheelOrderOut, WheelOut
from app.db import crud

__all__ = ["router"]

router = APIRouter(tags=["wheels"])


@router.get(
    "/runs/{run_id}/wheels",
    response_model=WheelList,
    summary="Wheel OOR of a run",
    responses={409: {"description": "The run has no results yet"}},
)
def get_wheels(run_id: RunId, db: DbDep) -> WheelList:
    """Per wheel: each OOR order as radius deviation (µm) with phase, and r(θ) on 360 angles."""
    with db.read() as session:
        if crud.get_run(session, run_id) is None:
            raise not_found("run", run_id)
        rows = crud.get_wheels(session, run_id)
        if not rows:
            latest = crud.latest_job(session, run_id)
            state = f"latest job {latest.id} is {latest.status}" if latest else "no job"
            raise ApiError(409, "wheels", f"run {run_id} has no results yet ({state})")
        items = [
            WheelOut(
                wheel=row.wheel,
                job_id=row.job_id,
                wheel_diameter_m=row.wheel_diameter_m,
                n_windows=row.n_windows,
                orders=[WheelOrderOut(**o) for o in (row.orders or [])],
                angles_deg=list(row.angles_deg or []),
                profile_um=list(row.profile_um or []),
                profile_p05_um=row.profile_p05_um,
                profile_p95_um=row.profile_p95_um,
            )
            for row in rows
        ]
    return WheelList(run_id=run_id, items=items)
