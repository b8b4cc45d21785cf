"""Parquet input: one numeric column per channel, optional ``time`` column."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from app.core.i18n import _
from app.io.channels import TIME_COLUMN
from app.io.errors import RunFileError
from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.sources.base import Source, SourceInfo, map_channel_names

__all__ = ["ParquetSource"]

_PANDAS_INDEX = "__index_level_0__"
_MAGIC = b"PAR1"
_READ_BUFFER_BYTES = 1 << 20


def _check_footer(path: Path, file_bytes: int, limits: IngestLimits) -> None:
    """Check the footer length stored in the last 8 bytes before the footer is parsed."""
    if file_bytes < 12:
        raise RunFileError("file", _("not a Parquet file: too short"))
    with open(path, "rb") as fh:
        fh.seek(file_bytes - 8)
        tail = fh.read(8)
    if tail[4:] != _MAGIC:
        raise RunFileError("file", _("not a Parquet file: no PAR1 magic at the end (truncated?)"))
    footer = int.from_bytes(tail[:4], "little")
    if footer > file_bytes - 12:
        raise RunFileError("file", _("Parquet footer of {footer} bytes does not fit the file (truncated?)", footer=footer))
    if footer > limits.max_parquet_footer_bytes:
        raise RunFileError(
            "file", _("Parquet footer of {footer} bytes exceeds {max_parquet_footer_bytes} bytes", footer=footer, max_parquet_footer_bytes=limits.max_parquet_footer_bytes)
        )


class ParquetSource(Source):
    """Read a Parquet file batch by batch (bounded memory).

    Before any column is read, the footer size (``limits.max_parquet_footer_bytes``),
    the column count (``limits.max_columns``) and the decoded size (rows ×
    columns × 8 bytes, and the uncompressed size of the column chunks) against
    ``limits.max_decoded_bytes(file size)`` are checked: a decompression or
    encoding bomb is refused from its metadata.

    Parameters
    ----------
    path : Path
        Input file.
    limits : IngestLimits
        Footer size, column count and decoded size limits (see above).
    """

    def __init__(self, path: Path, limits: IngestLimits = DEFAULT_LIMITS) -> None:
        path = Path(path)
        file_bytes = path.stat().st_size
        _check_footer(path, file_bytes, limits)
        try:
            # read page by page through a small buffer: memory does not grow with the row groups
            self._pf = pq.ParquetFile(path, pre_buffer=False, buffer_size=_READ_BUFFER_BYTES)
        except (pa.ArrowException, OSError) as exc:
            raise RunFileError("file", _("cannot open Parquet file: {error}", error=exc)) from None
        self._set_up_or_close(lambda: self._setup(file_bytes, limits))

    def _setup(self, file_bytes: int, limits: IngestLimits) -> None:
        meta = self._pf.metadata
        if meta.num_columns > limits.max_columns:
            raise RunFileError(
                "file", _("{num_columns} columns exceed the limit of {max_columns}", num_columns=meta.num_columns, max_columns=limits.max_columns)
            )
        allowed = limits.max_decoded_bytes(file_bytes)
        decoded = int(meta.num_rows) * 8 * meta.num_columns
        uncompressed = sum(
            max(int(meta.row_group(i).column(j).total_uncompressed_size), 0)
            for i in range(meta.num_row_groups)
            for j in range(meta.num_columns)
        )
        if max(decoded, uncompressed) > allowed:
            raise RunFileError(
                "file",
                _("the Parquet data decode to {decoded} bytes, more than {allowed} bytes allowed for a {file_bytes}-byte file (decompression bomb limit)", decoded=max(decoded, uncompressed), allowed=allowed, file_bytes=file_bytes),
            )
        schema = self._pf.schema_arrow
        names = [n for n in schema.names if n != _PANDAS_INDEX]
        self._names = map_channel_names(names)
        for orig in self._names:
            typ = schema.field(orig).type
            if not (pa.types.is_integer(typ) or pa.types.is_floating(typ)):
                raise RunFileError(orig, _("wrong dtype {typ}: channels must be numeric", typ=typ))
        canon = list(self._names.values())
        self.info = SourceInfo(
            channels=[c for c in canon if c != TIME_COLUMN],
            has_time=TIME_COLUMN in canon,
            n_samples=int(self._pf.metadata.num_rows),
        )

    def blocks(self, size: int) -> Iterator[dict[str, np.ndarray]]:
        cols = list(self._names)
        try:
            for batch in self._pf.iter_batches(batch_size=size, columns=cols):
                block: dict[str, np.ndarray] = {}
                for orig in cols:
                    arr = batch.column(batch.schema.get_field_index(orig))
                    block[self._names[orig]] = np.asarray(
                        arr.to_numpy(zero_copy_only=False), dtype=np.float64
                    )
                yield block
        except (pa.ArrowException, OSError) as exc:
            raise RunFileError("file", _("cannot read Parquet file: {error}", error=exc)) from None

    def close(self) -> None:
        self._pf.close()
