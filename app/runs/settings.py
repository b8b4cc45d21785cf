"""The uploads' settings group (``TRACKVKF_MAX_UPLOAD_BYTES``, ``TRACKVKF_UPLOAD_*``, ``TRACKVKF_PARSE_*``):
how run files are received, checked and parsed (:mod:`app.runs.upload`, :mod:`app.io.isolation`)."""

from __future__ import annotations

from pydantic import Field

from app.core.config import GIB, SettingsGroup

__all__ = ["UploadSettings"]


class UploadSettings(SettingsGroup):
    """Uploads: how run files are received, limited and parsed.

    Attributes
    ----------
    max_upload_bytes : int
        Largest accepted upload body, bytes (default 8 GiB). Larger uploads get 413.
    upload_block_bytes : int
        Size of the blocks an upload is read and written in, bytes.
    max_metadata_bytes : int
        Largest accepted metadata JSON document, bytes.
    upload_ingest_concurrency : int
        Uploads each API process validates and converts at once (the others
        wait their turn, already received): conversion holds the GIL, and
        more at once would starve the process's reads (:mod:`app.operations.heavy`).
    upload_stale_after_s : float
        Age (s) after which an upload directory is swept at start-up on a file
        system without ``flock`` (some network file systems). Elsewhere every
        upload no live API process owns (a process holds a ``flock`` on its
        uploads) is swept at start-up, whatever its age.
    upload_rate_limit, upload_rate_window_s : int, float
        At most ``upload_rate_limit`` uploads per principal (API key or user)
        within ``upload_rate_window_s`` seconds (per API process).
    parse_isolated : bool
        Parse uploaded run files, geometries and reference files in a child
        process with a time and memory budget (default true; see
        docs/security.md, "Parsers").
    parse_seconds : float
        Wall-clock budget of one parse, s, plus the file size divided by
        ``parse_min_bytes_per_s`` (default 120 s).
    parse_min_bytes_per_s : float
        Slowest accepted parse rate, bytes/s (default 1 MB/s; a 26 MB MDF4
        file ingests at about 10–20 MB/s on one busy core).
    parse_memory_bytes : int
        Growth of a parse child's data segment, bytes (default 4 GiB).
    """

    max_upload_bytes: int = Field(default=8 * GIB, gt=0)
    upload_block_bytes: int = Field(default=1024 * 1024, ge=4096)
    max_metadata_bytes: int = Field(default=1024 * 1024, ge=1024)
    upload_ingest_concurrency: int = Field(default=1, ge=1, le=64)
    upload_stale_after_s: float = Field(default=6 * 3600.0, gt=0)
    upload_rate_limit: int = Field(default=60, ge=1)
    upload_rate_window_s: float = Field(default=3600.0, gt=0)
    parse_isolated: bool = True
    parse_seconds: float = Field(default=120.0, gt=0)
    parse_min_bytes_per_s: float = Field(default=1_000_000.0, gt=0)
    parse_memory_bytes: int = Field(default=4 * GIB, ge=64 * 1024 * 1024)
