"""``GET /condition/report.pdf`` — the planning meeting's report of a line and track (PDF)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

from fastapi import APIRouter, Query, Request, Response
from starlette.concurrency import run_in_threadpool

from app.api.condition import LineIdQ, TrackQ
from app.api.deps import DbDep, SettingsDep
from app.api.language import request_language
from app.core.i18n import Language, translations
from app.places.report import Speech, line_report

__all__ = ["router"]

router = APIRouter(prefix="/condition", tags=["condition"])


def report_speech(language: Language) -> Speech:
    """The report's :class:`~app.places.report.Speech` in ``language`` (its catalogue, the pages'
    words of codes, numbers and dates in its locale)."""
    # app.web imports the API's routes: its words are read when a report is made
    from app.web.vocabulary import labels

    words = labels(language.code)
    t = translations(language.code)
    return Speech(lang=language.code, tag=language.tag, catalogue=t.gettext, plural=t.ngettext,
                  label=lambda kind, code: words.get(kind, {}).get(code, code.replace("_", " ")))


@router.get("/report.pdf", summary="The planning meeting's report of a line and track (PDF)",
            response_class=Response, responses={200: {"content": {"application/pdf": {}}}})
async def report_pdf(
    request: Request,
    db: DbDep,
    settings: SettingsDep,
    line_id: LineIdQ,
    track: TrackQ = None,
    date: Annotated[dt.date | None, Query(description="the meeting's date printed on the report (default: today, UTC)")] = None,
) -> Response:
    """Section classes in the railway's scheme and their change over the year, the work list, a
    sheet per open place (history plot, where on the line and on the map, maintenance over it),
    the maintenance effects, in the user's language (kept with the account, else the browser's).
    Takes a few seconds (made on request)."""
    speech = report_speech(request_language(request))
    data, pdf = await run_in_threadpool(line_report, db, settings, line_id, track, date=date, speech=speech)
    name = f"report-{data.line_id}-{data.track}-{data.date.isoformat()}.pdf"
    return Response(pdf, media_type="application/pdf", headers={"Content-Disposition": f'attachment; filename="{name}"'})
