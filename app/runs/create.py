"""A run created from an uploaded file: the file ingested (validated, converted to the canonical
HDF5 file), the run row and its first processing job inserted, the upload moved to the run's
directory, the audit entry written; or the existing run when the same file (sha256) was uploaded
before, with the same metadata (409 naming ``metadata`` otherwise: a correction goes through
``PATCH /runs/{id}``, :mod:`app.runs.metadata`).

The HTTP side (the streamed body, multipart parsing, the upload's rate limit) is
:mod:`app.api.upload`; it hands the received file here (:func:`create_run_from_file`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy.exc import IntegrityError

from app.analysis.settings import ProcessingSettings
from app.audit import record
from app.core.config import API_PREFIX
from app.core.errors import ApiError
from app.core.i18n import _, stored_message
from app.core.ids import MAX_ID
from app.core.jsonable import jsonable
from app.core.runstore import RunStore
from app.core.security import Actor
from app.db import crud, recorder_crud
from app.db.models import Run, utcnow
from app.db.session import Database
from app.io import RunSummary
from app.io.channel_map import ChannelMap, parse_channel_map
from app.io.geometry import LineGeometry
from app.io.isolation import ingest_upload
from app.runs.metadata import describe_differences, metadata_differences, run_fields
from app.settings import Settings

__all__ = ["UploadedFile", "UploadOutcome", "create_run_from_file", "existing_outcome", "existing_run_id",
           "check_same_metadata", "insert_run", "load_channel_map", "channel_map_id"]

log = logging.getLogger(__name__)

@dataclass(frozen=True)
class UploadedFile:
    """A file received by the API: where it is, its sha256 (hex), size in bytes and client file name."""

    path: Path
    sha256: str
    size: int
    filename: str | None = None


@dataclass
class UploadOutcome:
    """Result of an upload: the run id and whether it was created now."""

    run_id: int
    created: bool


def _run_row(summary: RunSummary, file: UploadedFile, fmt: str | None, principal_name: str) -> Run:
    return Run(
        sha256=file.sha256,
        file_path="",
        source_format=summary.source_format or fmt or "unknown",
        original_filename=file.filename,
        size_bytes=file.size,
        **run_fields(summary),
        ingest_report=jsonable({"warnings": list(summary.warnings),
                                "warning_messages": [stored_message(w) for w in summary.warnings],
                                "report": dict(summary.report)}),
        created_by=principal_name,
        created_at=utcnow(),
    )


def existing_run_id(db: Database, sha256: str) -> int | None:
    with db.read() as session:
        run = crud.get_run_by_sha256(session, sha256)
        return run.id if run is not None else None


def check_same_metadata(db: Database, run_id: int, given: dict[str, Any] | None) -> None:
    """The same file again: 409 when the given metadata differ from the run's (a correction
    goes through ``PATCH /runs/{id}``; keeping either version silently would lose one)."""
    if not given:
        return
    with db.read() as session:
        run = crud.get_run(session, run_id)
        stored = dict(run.meta or {}) if run is not None else None
    if stored is None:
        return
    diffs = metadata_differences(stored, given)
    if diffs:
        raise ApiError(
            409, "metadata",
            _("this file was uploaded before as run {run_id} with other metadata ({differences}); correct the run's metadata with PATCH {prefix}/runs/{run_id} (re-ingests and reprocesses the run)", run_id=run_id, differences=describe_differences(diffs), prefix=API_PREFIX),
        )


def load_channel_map(db: Database, map_id: int, vehicle_id: str | None) -> ChannelMap:
    """The stored channel map ``map_id``, checked against the run's vehicle.

    Raises
    ------
    ApiError
        422 naming ``channel_map`` when it does not exist or belongs to another vehicle.
    """
    with db.read() as session:
        row = recorder_crud.get_channel_map(session, map_id)
        if row is None:
            raise ApiError(422, "channel_map", _("channel map {map_id} not found", map_id=map_id))
        if vehicle_id is not None and row.vehicle_id != vehicle_id:
            raise ApiError(
                422, "channel_map",
                _("channel map {map_id} belongs to vehicle {vehicle_id}, the run's vehicle_id is {run_vehicle}", map_id=map_id, vehicle_id=repr(row.vehicle_id), run_vehicle=repr(vehicle_id)),
            )
        return parse_channel_map({"name": row.name, "channels": dict(row.channels)})


def channel_map_id(text: str | None) -> int | None:
    if text is None or not text.strip():
        return None
    value = text.strip()
    if not value.isdigit() or not 0 < int(value) <= MAX_ID:
        raise ApiError(422, "channel_map", _("must be the id of a stored channel map, got {value}", value=repr(value[:40])))
    return int(value)


def insert_run(
    db: Database,
    store: RunStore,
    upload_dir: Path,
    summary: RunSummary,
    file: UploadedFile,
    fmt: str | None,
    actor: Actor,
) -> int:
    """Insert the run, its queued job (default settings) and the audit entry; move the upload to the
    run's directory.

    The directory is moved (and the run file published to the shared store, if
    any) inside the transaction; if that or the commit fails, both are removed
    again.
    """
    installed: int | None = None
    try:
        with db.write() as session:
            run = _run_row(summary, file, fmt, actor.name)
            session.add(run)
            session.flush()
            run.file_path = store.relative_run_file(run.id)
            job = crud.create_job(session, run.id, ProcessingSettings().to_dict(), actor.name)
            record(session, actor, "run.upload", target=run.id, detail={
                "sha256": file.sha256, "size_bytes": file.size,
                "filename": file.filename, "format": run.source_format, "job_id": job.id,
            })
            store.install_run_dir(upload_dir, run.id)
            installed = run.id
            store.publish_run_file(run.id)  # to the shared store, if any, before the job is visible
        return installed
    except BaseException:
        if installed is not None:
            store.remove_run(installed)
        raise


def existing_outcome(db: Database, sha256: str, metadata: dict[str, Any] | None) -> UploadOutcome | None:
    """The existing run of a file uploaded before (409 naming ``metadata`` when the given metadata
    differ from the run's), or None for a new file."""
    existing = existing_run_id(db, sha256)
    if existing is None:
        return None
    check_same_metadata(db, existing, metadata)
    return UploadOutcome(run_id=existing, created=False)


def create_run_from_file(
    db: Database,
    store: RunStore,
    upload_dir: Path,
    file: UploadedFile,
    *,
    fmt: str | None,
    metadata: dict[str, Any] | None,
    channel_map: str | None,
    actor: Actor,
    settings: Settings,
) -> UploadOutcome:
    """The run of a received file: the existing one (same sha256), or a new one with its queued job.

    ``channel_map``: the id of a stored channel map as given (recorder files). The file is
    ingested into ``upload_dir / "run.h5"`` in a child process with a time and memory budget
    (:func:`app.io.isolation.ingest_upload`, ``TRACKVKF_PARSE_*``; a :class:`~app.io.RunFileError`
    names the field at fault), the upload itself then removed; ``settings.min_free_bytes`` stay
    free on the disk. Runs in a worker thread.

    Raises
    ------
    ApiError
        409 (``metadata``) for the same file with other metadata; 422 (``channel_map``) for a
        channel map that is not stored or belongs to another vehicle.
    """
    existing = existing_outcome(db, file.sha256, metadata)
    if existing is not None:
        return existing

    map_id = channel_map_id(channel_map)
    cmap = None
    if map_id is not None:
        vehicle = (metadata or {}).get("vehicle_id")
        cmap = load_channel_map(db, map_id, vehicle if isinstance(vehicle, str) else None)

    def geometry(line_id: str, track: str) -> LineGeometry | None:
        with db.read() as session:
            row = recorder_crud.find_geometry(session, line_id, track)
            return recorder_crud.to_line_geometry(row) if row is not None else None

    summary = ingest_upload(  # in a child process with a time and memory budget
        settings, file.path, fmt, metadata, upload_dir / "run.h5", channel_map=cmap, geometry=geometry,
        reserve_bytes=settings.min_free_bytes,
    )
    file.path.unlink()
    try:
        run_id = insert_run(db, store, upload_dir, summary, file, fmt, actor)
    except IntegrityError:
        # The same file was uploaded concurrently and committed first.
        existing = existing_run_id(db, file.sha256)
        if existing is None:
            raise
        check_same_metadata(db, existing, metadata)
        return UploadOutcome(run_id=existing, created=False)
    log.info("run %s created from %s (%d bytes, sha256 %s)", run_id, fmt, file.size, file.sha256)
    return UploadOutcome(run_id=run_id, created=True)
