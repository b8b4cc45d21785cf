"""The exports of a run's profile: its stored rows (one wheel or all) in a km range, at a level,
with the stiffness index columns if asked, paged (never whole in memory) and streamed as CSV
or Parquet."""

from __future__ import annotations

import io
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass

import pandas as pd
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from app.analytics.stiffness_index import INDEX_COLUMNS, IndexContext
from app.core.csv_export import csv_lines, escape_cell
from app.db import results_reader
from app.db.models import PROFILE_VALUE_COLUMNS
from app.db.session import Database
from app.profiles.answer import aggregate
from app.profiles.query import level_ratio, results_context, run_index_context
from app.settings import Settings

__all__ = ["ProfileExport", "profile_export", "export_filename", "csv_stream", "parquet_stream"]

_EXPORT_PAGE = 50_000
_STREAM_BLOCK = 1024 * 1024


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
    if level_ratio(level, bin_length) == 1:
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
            yield aggregate(ctx.add_columns(df) if ctx is not None else df, level, bin_length)


@dataclass(frozen=True)
class ProfileExport:
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
        """The pages to write."""
        return _frames(db, self.job_id, self.wheels, self.km_from, self.km_to, self.level, self.bin_length,
                       self.index)

    def filename(self, ext: str) -> str:
        """``run-<id>-profile[_wheel-<w>]_<level>m.<ext>``."""
        return export_filename(self.run_id, self.wheel, self.level, ext)


def profile_export(db: Database, settings: Settings, run_id: int, *, wheel: str | None, km_from: float | None,
                   km_to: float | None, level: float, index: bool) -> ProfileExport:
    """The checked query of both exports: results of the wheel, level, the index's curves."""
    job_id, bin_length, wheels = results_context(db, run_id, wheel)
    level_ratio(level, bin_length)
    ctx = run_index_context(db, settings, run_id, bin_length) if index else None
    return ProfileExport(run_id, job_id, wheel, [wheel] if wheel else wheels, km_from, km_to, level, bin_length, ctx)


def export_filename(run_id: int, wheel: str | None, level: float, ext: str) -> str:
    """The file name of an export: ``run-<id>-profile[_wheel-<w>]_<level>m.<ext>``."""
    parts = [f"run-{run_id}-profile"]
    if wheel:
        parts.append(f"wheel-{wheel}")
    parts.append(f"{level:g}m")
    return "_".join(parts) + f".{ext}"


def csv_stream(export: ProfileExport, db: Database, lang: str | None = None) -> Iterator[bytes]:
    """The export as CSV, page by page (the header once; only the header without rows); numbers written by
    pyarrow, text cells through :func:`app.core.csv_export.escape_cell`; the header is the column names, or
    given ``lang`` their labels and units in it (written by :func:`app.core.csv_export.csv_lines`)."""
    header = True
    for df in export.frames(db):
        if header and lang is not None:
            yield next(csv_lines(list(df.columns), [], lang)).encode()
            header = False
        buffer = io.BytesIO()
        text = [c for c in df.columns if df[c].dtype == object]
        if text:  # the one rule of every CSV export: a text cell a spreadsheet would run is defused
            df = df.assign(**{c: df[c].map(escape_cell) for c in text})
        pa_csv.write_csv(
            pa.Table.from_pandas(df, preserve_index=False),
            buffer,
            pa_csv.WriteOptions(include_header=header, quoting_style="none"),
        )
        yield buffer.getvalue()
        header = False
    if header:  # no rows: still send the header line
        cols = ["wheel", "bin", "km", *PROFILE_VALUE_COLUMNS, *(INDEX_COLUMNS if export.index else ())]
        yield (",".join(cols) + "\n").encode() if lang is None else next(csv_lines(cols, [], lang)).encode()


def parquet_stream(export: ProfileExport, db: Database) -> Iterator[bytes]:
    """The export as Parquet: written page by page to a temporary file, streamed out in blocks, removed."""
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
