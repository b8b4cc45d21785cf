"""Run files in and out: validation, the canonical HDF5 form, read access.

See ``docs/run-format.md`` for the accepted inputs and the stored layout.
"""

from app.io.canonical import CanonicalWriter, atomic_output, write_run_hdf5
from app.io.channels import (
    ACCEL_CHANNELS,
    ALL_CHANNELS,
    AXLES,
    FORCE_CHANNELS,
    KINEMATIC_CHANNELS,
    UNITS,
    WHEELS,
)
from app.io.errors import RunFileError
from app.io.ingest import RunSummary, ingest
from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.metadata import Calibration, RunMetadata, load_metadata_json, parse_metadata
from app.io.runfile import RunFile, open_run

__all__ = [
    "ACCEL_CHANNELS",
    "ALL_CHANNELS",
    "AXLES",
    "FORCE_CHANNELS",
    "KINEMATIC_CHANNELS",
    "UNITS",
    "WHEELS",
    "Calibration",
    "CanonicalWriter",
    "DEFAULT_LIMITS",
    "IngestLimits",
    "RunFile",
    "RunFileError",
    "RunMetadata",
    "RunSummary",
    "atomic_output",
    "ingest",
    "load_metadata_json",
    "open_run",
    "parse_metadata",
    "write_run_hdf5",
]
