"""Indicator profiles of a run: JSON query, CSV and Parquet export (streamed)."""

from __future__ import annotations

import asyncio
import gzip
import hashlib
import io
import json
import math
import os
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Annotated, Literal

import anyio.to_thread
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq
from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.responses import StreamingResponse
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from app.analysis.aggregate import aggregate_profile, display_indices
from app.api.analytics_index import INDEX_COLUMNS, IndexContext, index_context
from app.api.deps import DbDep, RunId, SettingsDep, check_km, km_query
from app.api.errors import ApiError, not_found
from app.api.schemas.profiles import ProfileOut
from app.core.bytecache import ByteLRU
from app.core.config import Settings
from app.db import crud, results_reader
from app.db.display import display_rows, km_extent
from app.db.display_arrays import DisplayArrays
from app.db.models import PROFILE_VALUE_COLUMNS, Job, Run
from app.db.session import Database

__all__ = ["router", "AGGREGATED_COLUMNS", "PROFILE_CACHE_CONTROL"]

router = APIRouter(tags=["profiles"])

#: Columns aggregated to 1 / 10 / 100 m segments (mean, max, p95 of each).
AGGREGATED_COLUMNS: tuple[str, ...] = tuple(c for c in PROFILE_VALUE_COLUMNS if c != "n_samples")
_MAX_LEVEL_M = 10_000.0
_EXPORT_PAGE = 50_000
_STREAM_BLOCK = 1024 * 1024

Wheel = Annotated[
    str, Query(pattern=r"^[0-9A-Za-z]{1,8}$", description='Wheel: "11", "12", "41" or "42"')
]
OptionalWheel = Annotated[
    str | None,
    Query(pattern=r"^[0-9A-Za-z]{1,8}$", description="Wheel; all wheels when omitted"),
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

#: profile answers are immutable per published job: browsers keep them and revalidate (ETag)
PROFILE_CACHE_CONTROL = "private, no-cache"
#: bumped when the encoding of a profile answer changes (part of its ETag)
_ENCODING_VERSION = 1
#: km columns keep 6 decimals (1 mm); other columns 5 significant digits of their largest value
_KM_COLUMNS = frozenset({"km", "km_from", "km_to"})
_KM_DECIMALS = 6
_SIGNIFICANT = 5
_GZIP_MIN_BYTES = 1024
_GZIP_LEVEL = 1  # 0.7 ms for a map's 87 kB (level 5: 2.4 ms, 10 % fewer bytes)


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


def _columns(value: str | None, max_points: int | None) -> tuple[str, ...] | None:
    """The asked indicator columns (422 naming the unknown ones); sleeper_amp added for decimation."""
    if value is None:
        return None
    names = [c.strip() for c in value.split(",") if c.strip()]
    if not names:
        raise ApiError(422, "columns", "names no column")
    if max_points is not None and "sleeper_amp" not in names:
        names.append("sleeper_amp")  # decimation keeps the peaks of the sleeper amplitude
    try:
        return results_reader.profile_columns(names)[3:]
    except ValueError as exc:
        raise ApiError(422, "columns", str(exc).removeprefix("columns: ")) from None


def run_with_results(session: Session, run_id: int) -> tuple[Run, Job]:
    """The run and the job whose results are stored; 404 without the run, 409 without results."""
    run = crud.get_run(session, run_id)
    if run is None:
        raise not_found("run", run_id)
    job = results_reader.results_job(session, run_id)
    if job is None:
        latest = crud.latest_job(session, run_id)
        state = f"latest job {latest.id} is {latest.status}" if latest else "no job"
        raise ApiError(409, "profile", f"run {run_id} has no results yet ({state})")
    return run, job


def _index_context(db: Database, settings, run_id: int, bin_length: float) -> IndexContext:
    """The reference curves of the run's line for the ``index`` columns."""
    with db.read() as session:
        run = crud.get_run(session, run_id)
        line_id, track = (run.line_id, run.track) if run is not None else (None, None)
    return index_context(db, settings, line_id, track, bin_length)


def _swept(run_id: int, swept_at: datetime) -> ApiError:
    """410: the run's 25 cm rows were removed by the retention sweep."""
    return ApiError(410, "profile", f"the 25 cm rows of run {run_id} were removed by the retention sweep on "
                                    f"{swept_at.date().isoformat()} (TRACKVKF_PROFILE_RETENTION_DAYS); "
                                    "its 10 m / 100 m condition rows remain: GET /api/v1/condition/…")


def _results_context(
    db: Database, run_id: int, wheel: str | None, arrays: DisplayArrays | None = None
) -> tuple[int, float, list[str]]:
    """Job id and bin length of the stored results and the wheels; 404/409 if none, 410 when swept.

    With the process' ``arrays`` one query (the job shown and whether the run
    was swept) where the run has results.
    """
    with db.read() as session:
        shown = results_reader.results_job_and_sweep(session, run_id) if arrays is not None else None
        if shown is not None and arrays is not None:
            job_id, swept_at = shown
            if swept_at is not None:
                raise _swept(run_id, swept_at)
            bin_length, stored = arrays.job_layout(session, job_id)
            wheels = list(stored)
        else:
            run, job = run_with_results(session, run_id)
            if run.profiles_swept_at is not None:
                raise _swept(run_id, run.profiles_swept_at)
            job_id, bin_length = job.id, results_reader.bin_length_of(job)
            wheels = results_reader.stored_profile_wheels(session, job.id)
    if wheel is not None and wheel not in wheels:
        raise ApiError(
            404, "wheel", f"run {run_id} has no profile for wheel {wheel!r} (wheels: {', '.join(wheels)})"
        )
    return job_id, bin_length, wheels


def _level_ratio(level_m: float, bin_length: float) -> int:
    ratio = level_m / bin_length
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-9 * max(ratio, 1.0):
        raise ApiError(
            422, "level", f"must be a positive multiple of the bin length {bin_length} m, got {level_m}"
        )
    return int(k)


def _aggregate(
    df: pd.DataFrame, level_m: float, bin_length: float, columns: Sequence[str] | None = None
) -> pd.DataFrame:
    wanted = AGGREGATED_COLUMNS if columns is None else [c for c in columns if c in AGGREGATED_COLUMNS]
    wanted = [*wanted, *(c for c in INDEX_COLUMNS if c in df.columns)]
    out = aggregate_profile(df, level_m, list(wanted), bin_length)
    out.insert(0, "wheel", df["wheel"].iloc[0] if len(df) else "")
    return out


def _decimate(df: pd.DataFrame, max_points: int, column: str) -> pd.DataFrame:
    """At most ``max_points`` rows of ``df`` keeping the peaks of ``column``."""
    if len(df) <= max_points:
        return df
    km_col = "km" if "km" in df.columns else "km_from"
    idx = display_indices(
        df[km_col].to_numpy(dtype=np.float64),
        df[column].to_numpy(dtype=np.float64, na_value=np.nan),
        max_points,
    )
    return df.iloc[idx].reset_index(drop=True)


def _rows_json(head: dict, df: pd.DataFrame) -> bytes:
    """``layout=rows``: the rows as objects, serialised by pandas (fast, NaN -> null)."""
    values = df.replace([np.inf, -np.inf], np.nan)
    rows = values.to_json(orient="records", double_precision=15) if len(df) else "[]"
    return (json.dumps(head)[:-1] + ', "rows": ' + rows + "}").encode()


def _decimals(name: str, values: pd.Series) -> int:
    """Fixed decimals of a float column: 6 for km, else 5 significant digits of its largest value."""
    if name in _KM_COLUMNS:
        return _KM_DECIMALS
    finite = np.abs(values.to_numpy(dtype=np.float64, na_value=np.nan))
    finite = finite[np.isfinite(finite) & (finite > 0)]
    if not len(finite):
        return _SIGNIFICANT
    return int(min(max(_SIGNIFICANT - 1 - math.floor(math.log10(float(finite.max()))), 0), 15))


def _columns_json(head: dict, df: pd.DataFrame) -> bytes:
    """``layout=columns``: one array per column (the wheel is in the head), fixed decimals."""
    parts = []
    names = [c for c in df.columns if c != "wheel"]
    for name in names:
        col = df[name]
        if pd.api.types.is_float_dtype(col.dtype):
            if np.isinf(col.to_numpy()).any():
                col = col.replace([np.inf, -np.inf], np.nan)
            text = col.to_json(orient="values", double_precision=_decimals(name, col))
        elif pd.api.types.is_numeric_dtype(col.dtype) or pd.api.types.is_bool_dtype(col.dtype):
            text = col.to_json(orient="values")
        else:
            text = json.dumps(col.astype(object).where(col.notna(), None).tolist())
        parts.append(f"{json.dumps(name)}: {text}")
    head = {**head, "columns": names}
    return (json.dumps(head)[:-1] + ', "data": {' + ", ".join(parts) + "}}").encode()


def _etag(job_id: int, settings_rows: int, **query: object) -> str:
    """ETag of a profile answer: the job (immutable once published) and the normalised query.

    Weak (``W/``): the same answer is sent plain or gzip-encoded.
    """
    key = json.dumps({"v": _ENCODING_VERSION, "job": job_id, "max_rows": settings_rows, **query}, sort_keys=True)
    return 'W/"pf-' + hashlib.sha256(key.encode()).hexdigest()[:32] + '"'


def _matches(etag: str, if_none_match: str | None) -> bool:
    """Whether an ``If-None-Match`` header names ``etag`` or ``*`` (weak comparison, RFC 9110)."""
    if not if_none_match:
        return False
    tags = [t.strip().removeprefix("W/") for t in if_none_match.split(",")]
    return "*" in tags or etag.removeprefix("W/") in tags


def _accepts_gzip(request: Request) -> bool:
    accept = request.headers.get("accept-encoding", "")
    for part in accept.split(","):
        name, _, params = part.strip().partition(";")
        if name.strip().lower() in ("gzip", "*"):
            return params.replace(" ", "").lower() not in ("q=0", "q=0.0", "q=0.00", "q=0.000")
    return False


def _encoded(body: bytes) -> tuple[bytes, bytes | None]:
    """The body and, when worth it, its gzip encoding (kept together in the answer cache)."""
    return body, gzip.compress(body, _GZIP_LEVEL, mtime=0) if len(body) >= _GZIP_MIN_BYTES else None


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
    values = _columns(columns, max_points)
    if index and values is not None:
        values = tuple(dict.fromkeys([*values, "speed_mean", "sleeper_amp"]))
    job_id, bin_length, _ = await run_in_threadpool(
        _results_context, db, run_id, wheel, request.app.state.display_arrays
    )
    ctx = await run_in_threadpool(_index_context, db, settings, run_id, bin_length) if index else None
    k = _level_ratio(level, bin_length)
    if max_points is not None and max_points > settings.max_profile_rows:
        raise ApiError(422, "max_points", f"must be <= {settings.max_profile_rows}")
    etag = _etag(job_id, settings.max_profile_rows, wheel=wheel, km_from=km_from, km_to=km_to, level=level,
                 max_points=max_points, columns=values, layout=layout,
                 index=ctx.version() if ctx is not None else None)
    headers = {"ETag": etag, "Cache-Control": PROFILE_CACHE_CONTROL, "Vary": "Accept-Encoding"}
    if _matches(etag, request.headers.get("if-none-match")):
        return Response(status_code=304, headers=headers)
    cache: ByteLRU[tuple[bytes, bytes | None]] = request.app.state.profile_cache
    encoded = cache.get(etag)
    if encoded is None:
        query = _ProfileQuery(run_id, job_id, bin_length, k, wheel, km_from, km_to, level, max_points, values, layout,
                              ctx)
        body, encoded = await _compute_once(request, etag, db, settings, query)
        if encoded is None:  # too large to keep: sent as it is (the middleware compresses it on the way)
            return Response(content=body, media_type="application/json", headers=headers)
    body, gzipped = encoded
    if gzipped is not None and _accepts_gzip(request):
        return Response(content=gzipped, media_type="application/json",
                        headers={**headers, "Content-Encoding": "gzip"})
    return Response(content=body, media_type="application/json", headers=headers)


@dataclass(frozen=True)
class _ProfileQuery:
    """A checked profile query of one published job (what :func:`_profile_body` answers)."""

    run_id: int
    job_id: int
    bin_length: float
    k: int
    wheel: str
    km_from: float | None
    km_to: float | None
    level: float
    max_points: int | None
    values: tuple[str, ...] | None
    layout: str
    index: IndexContext | None = None


_Computed = tuple[bytes, tuple[bytes, bytes | None] | None]


def _compute(
    db: Database, settings: Settings, query: _ProfileQuery, keep_bytes: int, arrays: DisplayArrays | None
) -> _Computed:
    """The answer's body and, if at most ``keep_bytes`` long, its cache entry (body, gzip body)."""
    body = _profile_body(db, settings, query, arrays)
    return body, _encoded(body) if len(body) <= keep_bytes else None


async def _compute_once(
    request: Request, etag: str, db: Database, settings: Settings, query: _ProfileQuery
) -> _Computed:
    """Compute an answer (in a worker thread, at most ``profile_concurrency`` at once) and cache it.

    Requests for an answer already being computed in this process wait for that
    computation instead of repeating it (50 browsers opening the same map at
    once compute it once).
    """
    pending: dict[str, asyncio.Future[_Computed]] = request.app.state.profile_pending
    running = pending.get(etag)
    if running is not None:
        try:
            return await asyncio.shield(running)
        except asyncio.CancelledError:
            task = asyncio.current_task()
            if not running.cancelled() or (task is not None and task.cancelling()):
                raise
            # the request computing it went away (client gone): compute it for this one
            return await _compute_once(request, etag, db, settings, query)
    future: asyncio.Future[_Computed] = asyncio.get_running_loop().create_future()
    pending[etag] = future
    try:
        cache: ByteLRU[tuple[bytes, bytes | None]] = request.app.state.profile_cache
        result = await anyio.to_thread.run_sync(
            _compute, db, settings, query, cache.max_bytes // 4, request.app.state.display_arrays,
            limiter=request.app.state.profile_limiter,
        )
        if result[1] is not None:
            cache.put(etag, result[1], len(result[1][0]) + len(result[1][1] or b""))
        future.set_result(result)
        return result
    except asyncio.CancelledError:
        future.cancel()
        raise
    except BaseException as exc:
        future.set_exception(exc)
        future.exception()  # retrieved: no "never retrieved" warning when nobody else waited
        raise
    finally:
        del pending[etag]


def _profile_body(
    db: Database, settings: Settings, query: _ProfileQuery, arrays: DisplayArrays | None = None
) -> bytes:
    """The encoded profile answer of :func:`get_profile` (read, aggregate, decimate, encode).

    ``arrays``: the process' display arrays, which answer display queries
    (``max_points`` at the stored bins) from memory where they can.
    """
    q = query
    run_id, job_id, bin_length, k, wheel = q.run_id, q.job_id, q.bin_length, q.k, q.wheel
    km_from, km_to, level, max_points, values = q.km_from, q.km_to, q.level, q.max_points, q.values
    ctx = q.index
    read = {"wheel": wheel, "km_from": km_from, "km_to": km_to, "columns": values}
    if values is not None and k > 1:  # a segment's 1-σ needs the shared part of its bins' (aggregate_profile)
        read["columns"] = [*values, *(f"{c}_shared" for c in values
                                      if f"{c}_shared" in PROFILE_VALUE_COLUMNS and f"{c}_shared" not in values)]
    in_memory = None
    if arrays is not None and max_points is not None and k == 1:  # a published job's arrays
        in_memory = arrays.display_rows(db, job_id, wheel, max_points, bin_length, km_from=km_from, km_to=km_to,
                                        columns=results_reader.profile_columns(values))
    if in_memory is not None:
        df, extent = in_memory
    else:
        with db.read() as session:  # one snapshot: the extent and the rows of the same job
            extent = km_extent(session, job_id, wheel)
            if max_points is not None and k == 1:
                # a few thousand rows of the stored display pyramid, whatever the range
                df = display_rows(session, job_id, wheel, max_points, bin_length, km_from=km_from, km_to=km_to,
                                  columns=results_reader.profile_columns(values), extent=extent)
            elif max_points is None and k == 1:
                df = results_reader.job_profile_frame(session, job_id, limit=settings.max_profile_rows + 1, **read)
            else:
                df = results_reader.job_profile_frame(session, job_id, **read)
    if ctx is not None:
        df = ctx.add_columns(df)
    truncated = False
    if max_points is not None and k > 1:
        df = _decimate(_aggregate(df, level, bin_length, values), max_points, "sleeper_amp_max")
    elif max_points is None:
        if k > 1:
            df = _aggregate(df, level, bin_length, values)
        truncated = len(df) > settings.max_profile_rows
        df = df.iloc[: settings.max_profile_rows]
    meta = ProfileOut(
        run_id=run_id,
        job_id=job_id,
        wheel=wheel,
        level_m=level,
        bin_length_m=bin_length,
        km_from=km_from,
        km_to=km_to,
        km_extent=list(extent) if extent is not None else None,
        max_points=max_points,
        n_rows=len(df),
        truncated=truncated,
        columns=list(df.columns),
        reference=ctx.describe() if ctx is not None else None,
    )
    head = meta.model_dump(mode="json", exclude={"rows", "data"})
    return _columns_json(head, df) if q.layout == "columns" else _rows_json(head, df)


def _frames(
    db: Database,
    job_id: int,
    wheels: list[str],
    km_from: float | None,
    km_to: float | None,
    level: float,
    bin_length: float,
    ctx: IndexContext | None = None,
) -> Iterator[pd.DataFrame]:
    """Pages of the export: stored rows, or aggregated segments wheel by wheel (with the
    stiffness index columns when ``ctx`` is given)."""
    if _level_ratio(level, bin_length) == 1:
        for wheel in wheels:
            for page in results_reader.iter_profile_pages(
                db.read, job_id, wheel, km_from=km_from, km_to=km_to, page_size=_EXPORT_PAGE
            ):
                yield ctx.add_columns(page) if ctx is not None else page
        return
    for wheel in wheels:
        with db.read() as session:
            df = results_reader.job_profile_frame(session, job_id, wheel=wheel, km_from=km_from, km_to=km_to)
        if len(df):
            yield _aggregate(ctx.add_columns(df) if ctx is not None else df, level, bin_length)


@dataclass(frozen=True)
class _Export:
    """What an export streams: a run's stored results (one wheel or all) in a km range, at a level."""

    run_id: int
    job_id: int
    wheel: str | None
    wheels: list[str]
    km_from: float | None
    km_to: float | None
    level: float
    bin_length: float
    index: IndexContext | None = None

    def frames(self, db: Database) -> Iterator[pd.DataFrame]:
        """The pages to write (:func:`_frames`)."""
        return _frames(db, self.job_id, self.wheels, self.km_from, self.km_to, self.level, self.bin_length,
                       self.index)

    def content_disposition(self, ext: str) -> dict[str, str]:
        """The attachment header naming the file ``run-<id>-profile[_wheel-<w>]_<level>m.<ext>``."""
        name = _filename(self.run_id, self.wheel, self.level, ext)
        return {"Content-Disposition": f'attachment; filename="{name}"'}


def _export_query(
    run_id: RunId,
    db: DbDep,
    settings: SettingsDep,
    wheel: OptionalWheel = None,
    km_from: KmFrom = None,
    km_to: KmTo = None,
    level: Level = 0.25,
    index: IndexQ = False,
) -> _Export:
    """The query of both export routes, checked: km bounds, results of the wheel, level."""
    check_km(km_from, km_to)
    job_id, bin_length, wheels = _results_context(db, run_id, wheel)
    _level_ratio(level, bin_length)
    ctx = _index_context(db, settings, run_id, bin_length) if index else None
    return _Export(run_id, job_id, wheel, [wheel] if wheel else wheels, km_from, km_to, level, bin_length, ctx)


ExportQuery = Annotated[_Export, Depends(_export_query)]


def _filename(run_id: int, wheel: str | None, level: float, ext: str) -> str:
    parts = [f"run-{run_id}-profile"]
    if wheel:
        parts.append(f"wheel-{wheel}")
    parts.append(f"{level:g}m")
    return "_".join(parts) + f".{ext}"


@router.get(
    "/runs/{run_id}/profile.csv",
    summary="Export the profile as CSV (streamed)",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/csv": {}}}, 409: {"description": "No results yet"}},
)
def export_csv(export: ExportQuery, db: DbDep) -> StreamingResponse:
    """All profile rows of a run (or one wheel) as CSV, in pages, never whole in memory."""

    def generate() -> Iterator[bytes]:
        header = True
        for df in export.frames(db):
            buffer = io.BytesIO()
            pa_csv.write_csv(
                pa.Table.from_pandas(df, preserve_index=False),
                buffer,
                pa_csv.WriteOptions(include_header=header, quoting_style="none"),
            )
            yield buffer.getvalue()
            header = False
        if header:  # no rows: still send the header line
            cols = ["wheel", "bin", "km", *PROFILE_VALUE_COLUMNS, *(INDEX_COLUMNS if export.index else ())]
            yield (",".join(cols) + "\n").encode()

    return StreamingResponse(generate(), media_type="text/csv", headers=export.content_disposition("csv"))


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

    def generate() -> Iterator[bytes]:
        fd, tmp = tempfile.mkstemp(suffix=".parquet", prefix="trackvkf-export-")
        os.close(fd)
        try:
            writer: pq.ParquetWriter | None = None
            try:
                for df in export.frames(db):
                    table = pa.Table.from_pandas(df, preserve_index=False)
                    if writer is None:
                        writer = pq.ParquetWriter(tmp, table.schema)
                    writer.write_table(table.cast(writer.schema))
                if writer is None:
                    empty = results_reader.profile_frame([])
                    if export.index is not None:
                        empty = export.index.add_columns(empty)
                    pq.write_table(pa.Table.from_pandas(empty, preserve_index=False), tmp)
            finally:
                if writer is not None:
                    writer.close()
            with open(tmp, "rb") as fh:
                while block := fh.read(_STREAM_BLOCK):
                    yield block
        finally:
            os.unlink(tmp)

    return StreamingResponse(
        generate(), media_type="application/vnd.apache.parquet", headers=export.content_disposition("parquet")
    )
