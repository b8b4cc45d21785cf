"""``GET /condition/sections`` — the section classes of a line (A … E per section from the
speed-conditioned stiffness index, the newest run) and the length per class now and a year before."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

from fastapi import APIRouter, Query
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from app.api.condition import LineIdQ, TrackQ
from app.api.deps import DbDep, SettingsDep
from app.api.errors import ApiError
from app.places.sections import SEGMENT_M, line_sections

__all__ = ["router"]

router = APIRouter(prefix="/condition", tags=["condition"])


class SectionOut(BaseModel):
    km_from: float
    km_to: float
    cls: str = Field(alias="class", serialization_alias="class", description='"A" (best) … "E"; "" without enough data')
    level: float | None = Field(description="mean index over the section, ln units")
    spread: float | None = Field(description="standard deviation of the index over the section, ln units")
    rms: float | None = Field(description="√(level² + spread²), the class is read from it, ln units")
    fill: float = Field(description="fraction of the section's 10 m segments with data")


class SectionsOut(BaseModel):
    line_id: str
    track: str
    quantity: str
    section_m: float
    limits: list[float] = Field(description="upper rms limits of the classes A, B, C, D (above: E)")
    classes: list[str]
    sections: list[SectionOut]
    length_by_class: dict[str, float] = Field(description='m per class ("": no class)')
    length_by_class_year_ago: dict[str, float] | None = Field(description="the same for the newest run at least 365 days older")
    run_id: int
    run_time: dt.datetime
    run_id_year_ago: int | None
    run_time_year_ago: dt.datetime | None


@router.get("/sections", response_model=SectionsOut, response_model_by_alias=True,
            summary="Section classes of a line (A … E per section) and the length per class")
async def sections(
    db: DbDep,
    settings: SettingsDep,
    line_id: LineIdQ,
    track: TrackQ = None,
    section_m: Annotated[int | None, Query(ge=SEGMENT_M, le=10_000, description="section length, m (a multiple of "
                                                                                "10; default TRACKVKF_PLACES_SECTION_M)")] = None,
) -> SectionsOut:
    """Per section of the newest run: level, spread and rms of the index, class A … E."""
    if section_m is not None and section_m % SEGMENT_M:
        raise ApiError(422, "section_m", f"must be a multiple of {SEGMENT_M} m, got {section_m}")
    out = await run_in_threadpool(line_sections, db, settings, line_id, track, section_m=section_m)
    return SectionsOut(**out)
