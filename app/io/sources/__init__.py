"""Block readers of the accepted input formats (HDF5, CSV, Parquet)."""

from __future__ import annotations

from pathlib import Path

from app.io.sources.base import Source, SourceInfo
from app.io.sources.csv import CsvSource
from app.io.sources.hdf5 import Hdf5Source
from app.io.sources.parquet import ParquetSource

__all__ = ["Source", "SourceInfo", "open_source"]


def open_source(path: Path, fmt: str, compression: str | None = None) -> Source:
    """Open an input file of a known format for block-wise reading.

    Parameters
    ----------
    path : Path
        Input file.
    fmt : {"hdf5", "csv", "parquet"}
        Its format.
    compression : str or None
        ``"gzip"`` for compressed CSV.
    """
    if fmt == "hdf5":
        return Hdf5Source(path)
    if fmt == "csv":
        return CsvSource(path, compression)
    if fmt == "parquet":
        return ParquetSource(path)
    raise ValueError(f"fmt: unknown format {fmt!r}")
