"""CSV input: a header row, one column per channel, optional ``time`` column."""

from __future__ import annotations

import gzip
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd

from app.io.channels import TIME_COLUMN
from app.io.errors import RunFileError
from app.io.sources.base import Source, SourceInfo, map_channel_names

__all__ = ["CsvSource"]


def _first_line(path: Path, compression: str | None) -> str:
    opener = gzip.open if compression == "gzip" else open
    try:
        with opener(path, "rb") as fh:
            raw = fh.readline(65536)
    except (OSError, EOFError) as exc:
        raise RunFileError("file", f"cannot read CSV file: {exc}") from None
    return raw.decode("utf-8", errors="replace").lstrip("\ufeff")


class CsvSource(Source):
    """Read a delimited text file in chunks (pandas ``chunksize``).

    The delimiter (``,``, ``;`` or tab) is taken from the header line. Empty
    cells and ``NaN``/``NA``/``null`` read as NaN.

    Parameters
    ----------
    path : Path
        Input file.
    compression : str or None
        ``"gzip"`` for a gzip-compressed file.
    """

    def __init__(self, path: Path, compression: str | None = None) -> None:
        self._path = path
        self._compression = compression
        header = _first_line(path, compression)
        if not header.strip():
            raise RunFileError("file", "CSV file has no header row")
        self._sep = next((s for s in (",", ";", "\t") if s in header), ",")
        columns = [c.strip().strip('"').strip("'") for c in header.rstrip("\r\n").split(self._sep)]
        self._names = map_channel_names(columns)
        self._columns = columns
        canon = list(self._names.values())
        self.info = SourceInfo(
            channels=[c for c in canon if c != TIME_COLUMN],
            has_time=TIME_COLUMN in canon,
        )

    def blocks(self, size: int) -> Iterator[dict[str, np.ndarray]]:
        try:
            reader = pd.read_csv(
                self._path,
                sep=self._sep,
                header=0,
                names=self._columns,
                chunksize=size,
                compression=self._compression,
                skipinitialspace=True,
                encoding="utf-8-sig",
                engine="c",
            )
            row = 0
            with reader:
                for chunk in reader:
                    block: dict[str, np.ndarray] = {}
                    for orig, canon in self._names.items():
                        block[canon] = _numeric(chunk[orig], orig, row)
                    row += len(chunk)
                    yield block
        except RunFileError:
            raise
        except pd.errors.EmptyDataError:
            return
        except (pd.errors.ParserError, UnicodeDecodeError, OSError, EOFError, ValueError) as exc:
            raise RunFileError("file", f"cannot parse CSV: {exc}") from None


def _numeric(col: pd.Series, name: str, row0: int) -> np.ndarray:
    if pd.api.types.is_bool_dtype(col.dtype):
        raise RunFileError(name, "wrong dtype bool: channels must be numeric")
    if pd.api.types.is_numeric_dtype(col.dtype):
        return col.to_numpy(dtype=np.float64, na_value=np.nan)
    values = pd.to_numeric(col, errors="coerce")
    bad = values.isna() & col.notna()
    if bad.any():
        i = int(np.flatnonzero(bad.to_numpy())[0])
        raise RunFileError(
            name, f"wrong dtype: non-numeric value {col.iloc[i]!r} in data row {row0 + i + 1}"
        )
    return values.to_numpy(dtype=np.float64, na_value=np.nan)
