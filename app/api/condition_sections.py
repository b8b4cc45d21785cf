"""``GET /condition/sections`` — the section classes of a line (A … E per section from the
speed-conditioned stiffness index, the newest run) and the length per class now and a year before."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from app.api.condition import LineIdQ, TrackQ
from app.api.csv_header import CsvLanguage
from app.api.deps import DbDep, SettingsDep
from app.api.errors import ApiError
from app.api.language import request_language
from app.core.i18n import _
from app.places.sections import SEGMENT_M, line_sections, sections_csv

__all__ = ["router"]

router = APIRouter(prefix="/condition", tags=["condition"])

SectionQ = Annotated[int | None, Query(ge=SEGMENT_M, le=10_000, description="section length, m (a multiple of "
                                                                           "10; default TRACKVKF_PLACES_SECTION_M)")]


def _checked_sections(db: Any, settings: Any, line_id: str, track: str | None, section_m: int | None,
                      lang: str) -> dict:
    if section_m is not None and section_m % SEGMENT_M:
        raise ApiError(422, "section_m", _("must be a multiple of {SEGMENT_M} m, got {section_m}", SEGMENT_M=SEGMENT_M, section_m=section_m))
    return line_sections(db, settings, line_id, track, section_m=section_m, lang=lang)


class SectionOut(BaseModel):
    km_from: float
    km_to: float
    cls: str = Field(alias="class", serialization_alias="class", description='"A" (best) … "E"; "" without enough data')
    scheme_class: str = Field(description="the code of its class in the railway's scheme (TRACKVKF_PLACES_CLASS_SCHEME; "
                                          "default A … E); \"\" without enough data")
    level: float | None = Field(description="mean index over the section, ln units")
    spread: float | None = Field(description="standard deviation of the index over the section, ln units")
    rms: float | None = Field(description="√(level² + spread²), the class is read from it, ln units")
    fill: float = Field(description="fraction of the section's 10 m segments with data")


class SchemeClassOut(BaseModel):
    code: str
    name: str = Field(description="in the request's language")
    of: list[str] = Field(description="the internal classes (A … E) it holds")
    colour: str


class SchemeOut(BaseModel):
    name: str
    classes: list[SchemeClassOut] = Field(description="best first")


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
    scheme: SchemeOut = Field(description="the railway's class scheme the sections are also given in")
    length_by_scheme_class: dict[str, float] = Field(description='m per class of the scheme ("": no class)')
    length_by_scheme_class_year_ago: dict[str, float] | None
    run_id: int
    run_time: dt.datetime
    run_id_year_ago: int | None
    run_time_year_ago: dt.datetime | None


@router.get("/sections", response_model=SectionsOut, response_model_by_alias=True,
            summary="Section classes of a line (A … E per section) and the length per class")
async def sections(
    request: Request,
    db: DbDep,
    settings: SettingsDep,
    line_id: LineIdQ,
    track: TrackQ = None,
    section_m: SectionQ = None,
) -> SectionsOut:
    """Per section of the newest run: level, spread and rms of the index, class A … E and the
    class of the railway's scheme."""
    out = await run_in_threadpool(_checked_sections, db, settings, line_id, track, section_m,
                                  request_language(request).code)
    return SectionsOut(**out)


@router.get("/sections.csv", summary="Section classes of a line as CSV (with the class of the railway's scheme)",
            response_class=Response, responses={200: {"content": {"text/csv": {}}}})
async def sections_csv_export(
    request: Request,
    db: DbDep,
    settings: SettingsDep,
    lang: CsvLanguage,
    line_id: LineIdQ,
    track: TrackQ = None,
    section_m: SectionQ = None,
) -> Response:
    """The sections of ``GET /condition/sections``, one CSV row each; ``header=labels``: the header in
    the user's language."""
    out = await run_in_threadpool(_checked_sections, db, settings, line_id, track, section_m,
                                  request_language(request).code)
    return Response(sections_csv(out, lang), media_type="text/csv",
                    headers={"Content-Disposition": f'attachment; filename="sections-{out["line_id"]}-{out["track"]}.csv"'})
