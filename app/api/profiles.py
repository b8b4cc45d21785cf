"""Indicator profiles of a run: JSON query, CSV and Parquet export (streamed)."""

from __future__ import annotations

import io
import json
import os
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq
from fastapi import APIRouter, Depends, Query, Response
from fastapi.responses import StreamingResponse
from sqlalchemy.orm import Session

from app.analysis.aggregate import aggregate_profile, display_indices
from app.api.deps import DbDep, RunId, SettingsDep, check_km, km_query
from app.api.errors import ApiError, not_found
from app.api.schemas.profiles import ProfileOut
from app.db import crud, results_reader
from app.db.display import display_rows, km_extent
from app.db.models import PROFILE_VALUE_COLUMNS, Job, Run
from app.db.session import Database

__all__ = ["router", "AGGREGATED_COLUMNS"]

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


Columns = Annotated[
    str | None,
    Query(
        max_length=400,
        description="Comma-separated indicator columns to return besides wheel, bin and km "
        "(e.g. sleeper_amp,speed_mean); default all. Fewer columns read several times faster "
        "(a line view of long runs asks only for what it draws)",
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


def _results_context(db: Database, run_id: int, wheel: str | None) -> tuple[int, float, list[str]]:
    """Job id and bin length of the stored results and the wheels; 404/409 if none, 410 when swept."""
    with db.read() as session:
        run, job = run_with_results(session, run_id)
        if run.profiles_swept_at is not None:
            raise ApiError(410, "profile", f"the 25 cm rows of run {run_id} were removed by the retention sweep on "
                                           f"{run.profiles_swept_at.date().isoformat()} (TRACKVKF_PROFILE_RETENTION_DAYS); "
                                           "its 10 m / 100 m condition rows remain: GET /api/v1/condition/…")
        wheels = results_reader.stored_profile_wheels(session, job.id)
    if wheel is not None and wheel not in wheels:
        raise ApiError(
            404, "wheel", f"run {run_id} has no profile for wheel {wheel!r} (wheels: {', '.join(wheels)})"
        )
    return job.id, results_reader.bin_length_of(job), wheels


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


def _json_response(meta: ProfileOut, df: pd.DataFrame) -> Response:
    """The profile as JSON; rows are serialised by pandas (fast, NaN -> null)."""
    head = meta.model_dump(mode="json", exclude={"rows"})
    values = df.replace([np.inf, -np.inf], np.nan)
    rows = values.to_json(orient="records", double_precision=15) if len(df) else "[]"
    body = json.dumps(head)[:-1] + ', "rows": ' + rows + "}"
    return Response(content=body, media_type="application/json")


@router.get(
    "/runs/{run_id}/profile",
    response_model=ProfileOut,
    summary="Indicator profile of a run and wheel",
    responses={409: {"description": "The run has no results yet"}},
)
def get_profile(
    run_id: RunId,
    db: DbDep,
    settings: SettingsDep,
    wheel: Wheel,
    km_from: KmFrom = None,
    km_to: KmTo = None,
    level: Level = 0.25,
    max_points: MaxPoints = None,
    columns: Columns = None,
) -> Response:
    """Per-bin indicators of one wheel in a km range, or their aggregates per segment.

    With ``max_points`` the rows are decimated for display: a plot of a whole
    100 km run asks for a few thousand rows that keep every peak, and asks again
    with a narrower km range when the user zooms in.
    """
    check_km(km_from, km_to)
    values = _columns(columns, max_points)
    job_id, bin_length, _ = _results_context(db, run_id, wheel)
    k = _level_ratio(level, bin_length)
    read = {"wheel": wheel, "km_from": km_from, "km_to": km_to, "columns": values}
    if max_points is not None and max_points > settings.max_profile_rows:
        raise ApiError(422, "max_points", f"must be <= {settings.max_profile_rows}")
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
        rows=[],
    )
    return _json_response(meta, df)


def _frames(
    db: Database,
    job_id: int,
    wheels: list[str],
    km_from: float | None,
    km_to: float | None,
    level: float,
    bin_length: float,
) -> Iterator[pd.DataFrame]:
    """Pages of the export: stored rows, or aggregated segments wheel by wheel."""
    if _level_ratio(level, bin_length) == 1:
        for wheel in wheels:
            yield from results_reader.iter_profile_pages(
                db.read, job_id, wheel, km_from=km_from, km_to=km_to, page_size=_EXPORT_PAGE
            )
        return
    for wheel in wheels:
        with db.read() as session:
            df = results_reader.job_profile_frame(session, job_id, wheel=wheel, km_from=km_from, km_to=km_to)
        if len(df):
            yield _aggregate(df, level, bin_length)


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

    def frames(self, db: Database) -> Iterator[pd.DataFrame]:
        """The pages to write (:func:`_frames`)."""
        return _frames(db, self.job_id, self.wheels, self.km_from, self.km_to, self.level, self.bin_length)

    def content_disposition(self, ext: str) -> dict[str, str]:
        """The attachment header naming the file ``run-<id>-profile[_wheel-<w>]_<level>m.<ext>``."""
        name = _filename(self.run_id, self.wheel, self.level, ext)
        return {"Content-Disposition": f'attachment; filename="{name}"'}


def _export_query(
    run_id: RunId,
    db: DbDep,
    wheel: OptionalWheel = None,
    km_from: KmFrom = None,
    km_to: KmTo = None,
    level: Level = 0.25,
) -> _Export:
    """The query of both export routes, checked: km bounds, results of the wheel, level."""
    check_km(km_from, km_to)
    job_id, bin_length, wheels = _results_context(db, run_id, wheel)
    _level_ratio(level, bin_length)
    return _Export(run_id, job_id, wheel, [wheel] if wheel else wheels, km_from, km_to, level, bin_length)


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
            cols = ["wheel", "bin", "km", *PROFILE_VALUE_COLUMNS]
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
