"""Block readers of the accepted input formats (HDF5, CSV, Parquet, MDF4, TDMS)."""

from __future__ import annotations

from pathlib import Path

from app.core.i18n import _
from app.io.channel_map import ChannelMap
from app.io.errors import RunFileError
from app.io.formats import RECORDER_FORMATS
from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.sources.base import Source, SourceInfo
from app.io.sources.csv import CsvSource
from app.io.sources.hdf5 import Hdf5Source
from app.io.sources.mdf4 import Mdf4Reader
from app.io.sources.parquet import ParquetSource
from app.io.sources.recorder import RecorderSource
from app.io.sources.tdms import TdmsReader

__all__ = ["Source", "SourceInfo", "RECORDER_FORMATS", "open_source"]



def open_source(
    path: Path,
    fmt: str,
    compression: str | None = None,
    limits: IngestLimits = DEFAULT_LIMITS,
    channel_map: ChannelMap | None = None,
) -> Source:
    """Open an input file of a known format for block-wise reading.

    Parameters
    ----------
    path : Path
        Input file.
    fmt : {"hdf5", "csv", "parquet", "mdf4", "tdms"}
        Its format.
    compression : str or None
        ``"gzip"`` for compressed CSV.
    limits : IngestLimits
        Column count, header length and decompression limits checked while
        opening and reading.
    channel_map : ChannelMap or None
        Recorder channel → trackvkf channel (MDF4 and TDMS only).

    Raises
    ------
    RunFileError
        ``field == "channel_map"`` for a channel map with another format.
    """
    if fmt in RECORDER_FORMATS:
        reader = Mdf4Reader(path, limits) if fmt == "mdf4" else TdmsReader(path, limits)
        return RecorderSource(reader, channel_map, limits)
    if channel_map is not None:
        raise RunFileError(
            "channel_map",
            _("channel maps apply to recorder files ({items}), not {fmt}; name the columns/datasets of a run file as trackvkf's channels", items=', '.join(RECORDER_FORMATS), fmt=fmt),
        )
    if fmt == "hdf5":
        return Hdf5Source(path, limits)
    if fmt == "csv":
        return CsvSource(path, compression, limits)
    if fmt == "parquet":
        return ParquetSource(path, limits)
    raise ValueError(f"fmt: unknown format {fmt!r}")
