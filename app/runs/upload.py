"""What the service decides about a received run upload: its format, its metadata, the name it
is kept under, how often a principal may upload, and how a refused upload is answered and
audited. The HTTP side (the streamed body into the run store, multipart parsing, the size cap,
the accepted content types) is :mod:`app.api.upload`; the run itself is made by
:func:`app.runs.create.create_run_from_file`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.audit import record_now
from app.core.diskspace import DiskFullError, is_disk_full
from app.core.errors import ApiError
from app.core.i18n import _
from app.core.security import Actor
from app.db.session import Database
from app.io import RunFileError, load_metadata_json
from app.io.formats import CONTENT_TYPE_FORMATS, FORMATS, format_of_alias, format_of_name
from app.runs.create import UploadedFile

__all__ = [
    "Received",
    "Upload",
    "infer_format",
    "upload_of",
    "rate_key",
    "too_many_uploads",
    "refusal",
    "record_refusal",
]

log = logging.getLogger(__name__)

@dataclass
class Received:
    """An upload as received: the file in its upload directory, its sha256 and size, the client's
    file name and content type, and the form fields that came with it (multipart)."""

    path: Path
    sha256: str
    size: int
    filename: str | None = None
    content_type: str | None = None
    fields: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Upload:
    """What a run is created from: the file, its format (None: ingest inspects it), its metadata and
    the channel map as given."""

    file: UploadedFile
    fmt: str | None
    metadata: dict[str, Any] | None
    channel_map: str | None


def infer_format(explicit: str | None, filename: str | None, content_type: str | None) -> str | None:
    """The upload's format: explicit value, else file extension, else content type.

    Returns None when nothing tells (ingest then inspects the file).

    Raises
    ------
    ApiError
        422 naming ``format`` if ``explicit`` is not a supported format.
    """
    if explicit:
        fmt = format_of_alias(explicit)
        if fmt is None:
            raise ApiError(422, "format", _("unknown format {format}; supported formats are {choices}",
                                                    format=repr(explicit), choices=', '.join(FORMATS)))
        return fmt
    named = format_of_name(filename)
    if named is not None:
        return named[0]
    return CONTENT_TYPE_FORMATS.get(content_type) if content_type else None


def _one_of(name: str, form_value: str | None, query_value: str | None) -> str | None:
    if form_value is not None and query_value is not None:
        raise ApiError(422, name, _("given both as form field and as query parameter"))
    return form_value if form_value is not None else query_value


def _metadata(text: str | None) -> dict[str, Any] | None:
    if text is None or not text.strip():
        return None
    return load_metadata_json(text, field="metadata")  # RunFileError: 422 naming the field


def upload_of(received: Received, *, query_format: str | None = None, query_metadata: str | None = None,
              query_channel_map: str | None = None) -> Upload:
    """The upload a run is created from: format, metadata and channel map from the form fields or
    the query (not both), the file renamed to its known extension (helps ingest recognise e.g. a
    gzip-compressed CSV).

    Raises
    ------
    ApiError
        422 naming ``file`` (empty), ``format`` (unknown), or a value given both ways.
    RunFileError
        422 naming ``metadata`` (not a JSON object).
    """
    if received.size == 0:
        raise ApiError(422, "file", _("the uploaded file is empty"))
    path = received.path
    named = format_of_name(received.filename)
    if named is not None:
        path = path.rename(path.with_name(f"upload{named[1]}"))
        received.path = path
    fmt = infer_format(_one_of("format", received.fields.get("format"), query_format), received.filename,
                       received.content_type)
    metadata = _metadata(_one_of("metadata", received.fields.get("metadata"), query_metadata))
    channel_map = _one_of("channel_map", received.fields.get("channel_map"), query_channel_map)
    return Upload(UploadedFile(path, received.sha256, received.size, received.filename), fmt, metadata, channel_map)


def rate_key(actor: Actor) -> str:
    """Whose upload budget an upload counts against: the API key's, else the user's."""
    key_id = actor.principal.key_id if actor.principal is not None else None
    return f"key:{key_id}" if key_id is not None else f"user:{actor.name}"


def too_many_uploads(retry_after_s: float) -> ApiError:
    """The 429 of an upload over ``TRACKVKF_UPLOAD_RATE_LIMIT`` (``Retry-After`` in whole seconds)."""
    seconds = max(1, int(retry_after_s + 0.999))
    return ApiError(429, "rate_limit", _("too many uploads; retry in {seconds} s", seconds=seconds), {"Retry-After": str(seconds)})


def refusal(exc: BaseException) -> tuple[ApiError, str, ApiError | None]:
    """How a failed upload is answered and audited: the error the audit entry describes, its outcome
    (``rejected``: the client's input or a full disk; ``error``: not the client's fault, answered 500),
    and the error to answer instead of ``exc`` (507 ``storage`` for a full disk), or None."""
    if isinstance(exc, ApiError):
        return exc, "rejected", None
    if is_disk_full(exc):
        log.warning("upload refused: %s", exc)
        reason = exc.message if isinstance(exc, DiskFullError) else _("the run store or the database is full")
        full = ApiError(507, "storage", _("{reason}; the upload was not kept, free space and try again", reason=reason))
        return full, "rejected", full
    if isinstance(exc, RunFileError):
        return ApiError(422, exc.field, exc.message), "rejected", None
    return ApiError(500, "server", _("{type}: {exc}", type=type(exc).__name__, exc=exc)), "error", None


def record_refusal(db: Database, actor: Actor, error: ApiError, outcome: str) -> None:
    """The audit entry of a refused upload (``run.upload`` with its status, field and message); a
    failure to write it is logged (the client gets the refusal all the same)."""
    try:
        record_now(db, actor, "run.upload", outcome=outcome, detail={
            "status": error.status_code, "field": error.field, "message": error.message[:500],
        })
    except Exception:  # noqa: BLE001 - the client gets the rejection; the failure is logged
        log.exception("could not write the audit entry of a rejected upload")
