"""Block readers of the accepted input formats (HDF5, CSV, Parquet)."""

from __future__ import annotations

from pathlib import Path

from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.sources.base import Source, SourceInfo
from app.io.sources.csv import CsvSource
from app.io.sources.hdf5 import Hdf5Source
from app.io.sources.parquet import ParquetSource

__all__ = ["Source", "SourceInfo", "open_source"]


def open_source(
    path: Path, fmt: str, compression: str | None = None, limits: IngestLimits = DEFAULT_LIMITS
) -> Source:
    """Open an input file of a known format for block-wise reading.

    Parameters
    ----------
    path : Path
        Input file.
    fmt : {"hdf5", "csv", "parquet"}
        Its format.
    compression : str or None
        ``"gzip"`` for compressed CSV.
    limits : IngestLimits
        Column count, header length and decompression limits checked while
        opening and reading.
    """
    if fmt == "hdf5":
        return Hdf5Source(path, limits)
    if fmt == "csv":
        return CsvSource(path, compression, limits)
    if fmt == "parquet":
        return ParquetSource(path, limits)
    raise ValueError(f"fmt: unknown format {fmt!r}")
