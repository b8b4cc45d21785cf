"""What a parse child runs (:mod:`app.io.isolation`): imported once by the fork server.

Importing the parsing libraries here makes each child start with them loaded
(a fork costs milliseconds; importing asammdf, h5py, pyarrow and pyproj costs
seconds).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import asammdf  # noqa: F401 - preloaded for the children
import h5py  # noqa: F401
import nptdms  # noqa: F401
import pandas  # noqa: F401
import pyarrow.parquet  # noqa: F401
import pyproj  # noqa: F401
import shapely  # noqa: F401

from app.io.geometry import LineGeometry, parse_geojson
from app.io.ingest import RunSummary, ingest
from app.io.reference import read_reference

__all__ = ["ingest_file", "parse_geojson_file", "read_reference_file"]


def ingest_file(src: Path, fmt: str | None, metadata: Any, dest: Path, **kwargs: Any) -> RunSummary:
    """:func:`app.io.ingest.ingest` (the ``geometry`` lookup comes through the pipe)."""
    return ingest(src, fmt, metadata, dest, **kwargs)


def parse_geojson_file(data: bytes) -> list[LineGeometry]:
    """:func:`app.io.geometry.parse_geojson`."""
    return parse_geojson(data)


def read_reference_file(data: bytes, kind: str, fmt: str | None, filename: str | None) -> list[dict[str, Any]]:
    """:func:`app.io.reference.read_reference`."""
    return read_reference(data, kind, fmt, filename)  # type: ignore[arg-type]
