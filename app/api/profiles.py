"""Indicator profiles of a run: JSON query, CSV and Parquet export (streamed): the routes.

Each route checks its query (:mod:`app.profiles.query`) and answers through :mod:`app.profiles`:
the answer of a published job computed once per process and kept (:mod:`app.profiles.cache`),
its ETag and gzip encoding (:mod:`app.profiles.encoding`), the exports' streams
(:mod:`app.profiles.export`).
"""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from app.api.csv_header import CsvLanguage
from app.api.deps import DbDep, RunId, SettingsDep, check_km, km_query
from app.api.params import WHEEL_PATTERN
from app.api.schemas.profiles import ProfileOut
from app.profiles.cache import ProfileAnswers
from app.profiles.encoding import CACHE_CONTROL, accepts_gzip, matches
from app.profiles.export import ProfileExport, csv_stream, parquet_stream, profile_export
from app.profiles.query import AGGREGATED_COLUMNS, profile_query

__all__ = ["router", "AGGREGATED_COLUMNS", "PROFILE_CACHE_CONTROL"]

router = APIRouter(tags=["profiles"])

#: profile answers are immutable per published job: browsers keep them and revalidate (ETag)
PROFILE_CACHE_CONTROL = CACHE_CONTROL
_MAX_LEVEL_M = 10_000.0

#: the profile routes name a stored wheel: one the run has no rows of is a 404 naming ``wheel``
#: (app.profiles.query), not :func:`app.api.params.wheel_param`'s 422
Wheel = Annotated[
    str, Query(pattern=WHEEL_PATTERN, description='Wheel: "11", "12", "41" or "42"')
]
OptionalWheel = Annotated[
    str | None,
    Query(pattern=WHEEL_PATTERN, description="Wheel; all wheels when omitted"),
]
KmFrom = Annotated[float | None, km_query("Lower km bound of the bin centres")]
KmTo = Annotated[float | None, km_query("Upper km bound of the bin centres")]
Level = Annotated[
    float,
    Query(
        gt=0,
        le=_MAX_LEVEL_M,
        description="Segment length, m: 0.25 (the stored bins) or an aggregation level "
        "such as 1, 10 or 100 (mean, max, 95th percentile per segment)",
    ),
]
MaxPoints = Annotated[
    int | None,
    Query(
        ge=4,
        le=1_000_000,
        description="Display decimation: at most this many rows, chosen to keep the peaks "
        "(local minima and maxima) of the sleeper-passage amplitude "
        "(sleeper_amp, or sleeper_amp_max of segments); all rows when omitted",
    ),
]
Layout = Annotated[
    Literal["rows", "columns"],
    Query(
        description="rows (default): a list of row objects; columns: one array per column with "
        "fixed decimals (about a third of the bytes, quicker to encode and to plot; the dashboard "
        "asks for it)"
    ),
]
Columns = Annotated[
    str | None,
    Query(
        max_length=400,
        description="Comma-separated indicator columns to return besides wheel, bin and km "
        "(e.g. sleeper_amp,speed_mean); default all. Fewer columns read several times faster "
        "(a line view of long runs asks only for what it draws)",
    ),
]
IndexQ = Annotated[
    bool,
    Query(
        description="Add the stiffness index: stiffness_index = ln(sleeper_amp / reference_amp), "
        "stiffness_index_se (its standard uncertainty, ln units) and reference_amp (m/s², the "
        "amplitude of a typical location of the bin's superstructure class at the bin's speed, from "
        "the line's reference curves); null where the reference has no passes at that speed. The "
        "answer's `reference` says which curves were used",
    ),
]


@router.get(
    "/runs/{run_id}/profile",
    response_model=ProfileOut,
    summary="Indicator profile of a run and wheel",
    responses={409: {"description": "The run has no results yet"}},
)
async def get_profile(
    request: Request,
    run_id: RunId,
    db: DbDep,
    settings: SettingsDep,
    wheel: Wheel,
    km_from: KmFrom = None,
    km_to: KmTo = None,
    level: Level = 0.25,
    max_points: MaxPoints = None,
    columns: Columns = None,
    layout: Layout = "rows",
    index: IndexQ = False,
) -> Response:
    """Per-bin indicators of one wheel in a km range, or their aggregates per segment.

    With ``max_points`` the rows are decimated for display: a plot of a whole
    100 km run asks for a few thousand rows that keep every peak, and asks again
    with a narrower km range when the user zooms in.

    The answer of a published job never changes: it carries an ``ETag`` (the job
    and the query) and ``Cache-Control: private, no-cache``, a request with a
    matching ``If-None-Match`` gets ``304 Not Modified``, and the server keeps
    recent answers (gzip-encoded too) in memory (``TRACKVKF_PROFILE_CACHE_BYTES``
    per API process). A new job of the run changes the ETag (and, with ``index``, new
    reference curves of the line). At most
    ``TRACKVKF_PROFILE_CONCURRENCY`` answers per API process are computed at
    once; more wait their turn without holding up other requests (uploads, logins).
    """
    check_km(km_from, km_to)
    state = request.app.state
    query = await run_in_threadpool(
        profile_query, db, settings, state.display_arrays, run_id, wheel=wheel, km_from=km_from, km_to=km_to,
        level=level, max_points=max_points, columns=columns, layout=layout, index=index,
    )
    headers = {"ETag": query.etag, "Cache-Control": PROFILE_CACHE_CONTROL, "Vary": "Accept-Encoding"}
    if matches(query.etag, request.headers.get("if-none-match")):
        return Response(status_code=304, headers=headers)
    answers = ProfileAnswers(state.profile_cache, state.profile_limiter, state.display_arrays, state.profile_pending)
    body, kept = await answers.get(db, settings, query)
    if kept is not None and kept[1] is not None and accepts_gzip(request.headers.get("accept-encoding", "")):
        return Response(content=kept[1], media_type="application/json",
                        headers={**headers, "Content-Encoding": "gzip"})
    # an answer too large to keep is sent as it is (the middleware compresses it on the way)
    return Response(content=body, media_type="application/json", headers=headers)


def _export_query(
    run_id: RunId,
    db: DbDep,
    settings: SettingsDep,
    wheel: OptionalWheel = None,
    km_from: KmFrom = None,
    km_to: KmTo = None,
    level: Level = 0.25,
    index: IndexQ = False,
) -> ProfileExport:
    """The query of both export routes, checked: km bounds, results of the wheel, level."""
    check_km(km_from, km_to)
    return profile_export(db, settings, run_id, wheel=wheel, km_from=km_from, km_to=km_to, level=level, index=index)


ExportQuery = Annotated[ProfileExport, Depends(_export_query)]


def _attachment(export: ProfileExport, ext: str) -> dict[str, str]:
    return {"Content-Disposition": f'attachment; filename="{export.filename(ext)}"'}


@router.get(
    "/runs/{run_id}/profile.csv",
    summary="Export the profile as CSV (streamed)",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/csv": {}}}, 409: {"description": "No results yet"}},
)
def export_csv(export: ExportQuery, db: DbDep, lang: CsvLanguage) -> StreamingResponse:
    """All profile rows of a run (or one wheel) as CSV, in pages, never whole in memory; ``header=labels``:
    the header in the user's language."""
    return StreamingResponse(csv_stream(export, db, lang), media_type="text/csv", headers=_attachment(export, "csv"))


@router.get(
    "/runs/{run_id}/profile.parquet",
    summary="Export the profile as Parquet (streamed)",
    response_class=StreamingResponse,
    responses={
        200: {"content": {"application/vnd.apache.parquet": {}}},
        409: {"description": "No results yet"},
    },
)
def export_parquet(export: ExportQuery, db: DbDep) -> StreamingResponse:
    """All profile rows of a run (or one wheel) as Parquet.

    The file is written page by page to a temporary file, streamed out in
    blocks, and removed.
    """
    return StreamingResponse(
        parquet_stream(export, db), media_type="application/vnd.apache.parquet",
        headers=_attachment(export, "parquet"),
    )
