"""Rail findings of a line (dipped welds and joints followed over its runs; issue 33): the routes
(:mod:`app.condition.rail_findings`).

``GET /condition/rail-findings`` (``.csv``) — a line's findings, ascending km, with their type, dip depth,
runs seen out of runs passed and the depth's trend; ``GET /condition/rail-findings/{id}`` — one finding
with its sightings. Rail findings are never places: the store keeps them out of every graded row.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Query
from fastapi.responses import Response

from app.api.condition import LineIdQ, TrackQ
from app.api.csv_header import CsvLanguage
from app.api.deps import DbDep
from app.condition import rail_findings

__all__ = ["router"]

router = APIRouter(prefix="/condition", tags=["condition"])

TypeQ = Annotated[list[str] | None, Query(description="Finding type(s): " + ", ".join(rail_findings.FINDING_TYPES))]
SteadyQ = Annotated[bool, Query(description="Only the steady findings: seen by at least half the runs that "
                                            "passed them (the others are one-offs of a few passes)")]
FindingId = Annotated[str, Path(min_length=1, max_length=40, description="Rail finding id ({first run}-{dm})")]


@router.get("/rail-findings", summary="Rail findings of a line: welds and joints followed over its runs")
def findings(db: DbDep, line_id: LineIdQ, track: TrackQ = None, type: TypeQ = None,  # noqa: A002
             steady: SteadyQ = False) -> dict:
    """Each finding: its type (the register's where an asset lies on it, else weld or joint by the dip's
    length), km, the newest dip depth (mm), runs seen out of runs passed, whether that is at least half
    (``steady``), first and last seen, and the depth's trend (mm a year); ``unsteady``: how many of the
    type filter's findings are not steady."""
    return rail_findings.line_findings(db, line_id, track, type, steady_only=steady)


@router.get("/rail-findings.csv", summary="Rail findings of a line as CSV", response_class=Response,
            responses={200: {"content": {"text/csv": {}}}})
def findings_csv(db: DbDep, lang: CsvLanguage, line_id: LineIdQ, track: TrackQ = None,
                 type: TypeQ = None, steady: SteadyQ = False) -> Response:  # noqa: A002
    """One row per finding; ``header=labels``: the header in the user's language."""
    return Response(rail_findings.findings_csv(db, line_id, track, type, lang, steady_only=steady),
                    media_type="text/csv",
                    headers={"Content-Disposition": 'attachment; filename="rail-findings.csv"'})


@router.get("/rail-findings/{finding_id}", summary="A rail finding with its sightings")
def finding(db: DbDep, finding_id: FindingId) -> dict:
    """The finding and every run that saw it (position, depth, dip length), and the runs that passed it."""
    return rail_findings.finding(db, finding_id)
