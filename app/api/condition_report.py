"""``GET /condition/report.pdf`` — the planning meeting's report of a line and track (PDF)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

from fastapi import APIRouter, Query, Response
from starlette.concurrency import run_in_threadpool

from app.api.condition import LineIdQ, TrackQ
from app.api.deps import DbDep, SettingsDep
from app.places.report import line_report

__all__ = ["router"]

router = APIRouter(prefix="/condition", tags=["condition"])


@router.get("/report.pdf", summary="The planning meeting's report of a line and track (PDF)",
            response_class=Response, responses={200: {"content": {"application/pdf": {}}}})
async def report_pdf(
    db: DbDep,
    settings: SettingsDep,
    line_id: LineIdQ,
    track: TrackQ = None,
    date: Annotated[dt.date | None, Query(description="the meeting's date printed on the report (default: today, UTC)")] = None,
) -> Response:
    """Section classes in the railway's scheme and their change over the year, the work list, a
    sheet per open place (history plot, where on the line and on the map, maintenance over it),
    the maintenance effects. Takes a few seconds (made on request)."""
    data, pdf = await run_in_threadpool(line_report, db, settings, line_id, track, date=date)
    name = f"report-{data.line_id}-{data.track}-{data.date.isoformat()}.pdf"
    return Response(pdf, media_type="application/pdf", headers={"Content-Disposition": f'attachment; filename="{name}"'})
