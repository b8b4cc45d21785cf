"""Parquet input: one numeric column per channel, optional ``time`` column."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from app.io.channels import TIME_COLUMN
from app.io.errors import RunFileError
from app.io.sources.base import Source, SourceInfo, map_channel_names

__all__ = ["ParquetSource"]

_PANDAS_INDEX = "__index_level_0__"


class ParquetSource(Source):
    """Read a Parquet file batch by batch (bounded memory).

    Parameters
    ----------
    path : Path
        Input file.
    """

    def __init__(self, path: Path) -> None:
        try:
            self._pf = pq.ParquetFile(path)
        except (pa.ArrowException, OSError) as exc:
            raise RunFileError("file", f"cannot open Parquet file: {exc}") from None
        schema = self._pf.schema_arrow
        names = [n for n in schema.names if n != _PANDAS_INDEX]
        self._names = map_channel_names(names)
        for orig in self._names:
            typ = schema.field(orig).type
            if not (pa.types.is_integer(typ) or pa.types.is_floating(typ)):
                raise RunFileError(orig, f"wrong dtype {typ}: channels must be numeric")
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
            raise RunFileError("file", f"cannot read Parquet file: {exc}") from None

    def close(self) -> None:
        self._pf.close()
