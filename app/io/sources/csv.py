"""CSV input: a header row, one column per channel, optional ``time`` column."""

from __future__ import annotations

import gzip
import io
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd

from app.io.channels import TIME_COLUMN
from app.io.errors import RunFileError
from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.sources.base import Source, SourceInfo, map_channel_names

__all__ = ["CsvSource", "BoundedGzipReader"]


class BoundedGzipReader(io.RawIOBase):
    """A gzip file read as a binary stream that stops at a decompressed-size limit.

    Parameters
    ----------
    path : Path
        gzip-compressed file.
    limit : int
        Largest number of decompressed bytes; reading past it raises
        :class:`RunFileError` (``field == "file"``): a decompression bomb.
    """

    def __init__(self, path: Path, limit: int) -> None:
        super().__init__()
        self._gz = gzip.open(path, "rb")
        self._limit = int(limit)
        self.count = 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:  # noqa: ANN001 - a writable buffer
        view = memoryview(buffer)
        n = self._gz.readinto(view)
        self.count += n
        if self.count > self._limit:
            raise RunFileError(
                "file",
                f"the gzip file decompresses to more than {self._limit} bytes "
                "(decompression bomb limit, TRACKVKF ingest max_expansion_ratio)",
            )
        return n

    def close(self) -> None:
        self._gz.close()
        super().close()


def _open(path: Path, compression: str | None, limits: IngestLimits):
    if compression == "gzip":
        limit = limits.max_decoded_bytes(path.stat().st_size)
        return io.BufferedReader(BoundedGzipReader(path, limit), buffer_size=1 << 20)
    return open(path, "rb")  # noqa: SIM115 - closed by the caller


def _scan_gzip(path: Path, limits: IngestLimits) -> None:
    """Decompress once without parsing: a bomb is refused before pandas sees a byte."""
    try:
        with BoundedGzipReader(path, limits.max_decoded_bytes(path.stat().st_size)) as raw:
            buffer = bytearray(1 << 20)
            while raw.readinto(buffer):
                pass
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise RunFileError("file", f"cannot read gzip file: {exc}") from None


def _first_line(path: Path, compression: str | None, limits: IngestLimits) -> str:
    try:
        with _open(path, compression, limits) as fh:
            raw = fh.readline(limits.max_header_bytes + 1)
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise RunFileError("file", f"cannot read CSV file: {exc}") from None
    if len(raw) > limits.max_header_bytes or (
        len(raw) == limits.max_header_bytes and not raw.endswith(b"\n")
    ):
        raise RunFileError(
            "file",
            f"the header row is longer than {limits.max_header_bytes} bytes "
            f"(at most {limits.max_columns} columns are accepted)",
        )
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
        ``"gzip"`` for a gzip-compressed file (decompressed size bounded by
        ``limits.max_decoded_bytes``).
    limits : IngestLimits
        Header length and column count limits.
    """

    def __init__(
        self, path: Path, compression: str | None = None, limits: IngestLimits = DEFAULT_LIMITS
    ) -> None:
        self._path = path
        self._compression = compression
        self._limits = limits
        if compression == "gzip":
            _scan_gzip(path, limits)
        header = _first_line(path, compression, limits)
        if not header.strip():
            raise RunFileError("file", "CSV file has no header row")
        self._sep = next((s for s in (",", ";", "\t") if s in header), ",")
        n_columns = header.count(self._sep) + 1
        if n_columns > limits.max_columns:
            raise RunFileError(
                "file", f"{n_columns} columns exceed the limit of {limits.max_columns}"
            )
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
            handle = _open(self._path, self._compression, self._limits)
        except (OSError, gzip.BadGzipFile) as exc:
            raise RunFileError("file", f"cannot read CSV file: {exc}") from None
        try:
            reader = pd.read_csv(
                handle,
                sep=self._sep,
                header=0,
                names=self._columns,
                chunksize=size,
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
        finally:
            handle.close()


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
