"""Streamed run uploads: request body → run store, sha256, validation, run row.

Two request shapes are accepted on ``POST /api/v1/runs``:

``multipart/form-data``
    parts ``file`` (the run file, required), ``metadata`` (JSON object,
    optional for HDF5), ``format`` (``hdf5``, ``csv``, ``parquet``, ``mdf4``
    or ``tdms``, optional: else taken from the file name or the part's
    content type) and ``channel_map`` (id of a stored channel map, recorder
    files only).
any other content type (``application/octet-stream``, ``application/x-hdf5``,
``text/csv``, ``application/vnd.apache.parquet``)
    the body is the file; ``format``, ``metadata``, ``filename`` and
    ``channel_map`` come as query parameters.

The body is read block by block into ``<run_store>/.uploads/<token>/`` while
its sha256 is computed and its size checked against the cap; it is never held
in memory whole. The received file is then handed to the run service
(:func:`app.runs.create.create_run_from_file`): validated and converted by
:func:`app.io.ingest` to the canonical HDF5 file, and only then are the run
row and its processing job inserted and the directory moved to its final
place. Any failure removes the upload directory: no row, job or file remains.
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from python_multipart.exceptions import FormParserError
from python_multipart.multipart import MultipartParser, parse_options_header
from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect, Request

from app.api.deps import Actor
from app.api.errors import ApiError, run_file_error
from app.audit import record_now
from app.core.config import Settings
from app.core.diskspace import DiskFullError, is_disk_full, require_free
from app.core.runstore import RunStore
from app.db.session import Database
from app.io import RunFileError, load_metadata_json
from app.operations.heavy import run_heavy
from app.runs.create import UploadedFile, UploadOutcome, create_run_from_file, existing_outcome

__all__ = ["SUPPORTED_FORMATS", "UploadOutcome", "receive_and_create_run", "infer_format"]

log = logging.getLogger(__name__)

SUPPORTED_FORMATS: tuple[str, ...] = ("hdf5", "csv", "parquet", "mdf4", "tdms")
_FORMAT_ALIASES = {"h5": "hdf5", "hdf": "hdf5", "hdf5": "hdf5", "csv": "csv", "parquet": "parquet", "pq": "parquet",
                   "mdf4": "mdf4", "mf4": "mdf4", "mdf": "mdf4", "tdms": "tdms"}
_EXTENSIONS = {
    ".h5": "hdf5", ".hdf5": "hdf5", ".hdf": "hdf5", ".he5": "hdf5", ".mat": "hdf5",
    ".csv": "csv", ".tsv": "csv", ".txt": "csv",
    ".csv.gz": "csv", ".tsv.gz": "csv", ".txt.gz": "csv",
    ".parquet": "parquet", ".pq": "parquet",
    ".mf4": "mdf4", ".mdf": "mdf4", ".tdms": "tdms",
}
_CONTENT_TYPES = {
    "application/x-hdf5": "hdf5", "application/x-hdf": "hdf5", "application/hdf5": "hdf5",
    "text/csv": "csv", "application/csv": "csv",
    "application/vnd.apache.parquet": "parquet", "application/x-parquet": "parquet",
    "application/parquet": "parquet",
}
#: Content types accepted for a raw body or a multipart file part (besides none at all).
ACCEPTED_CONTENT_TYPES: frozenset[str] = frozenset(
    {*_CONTENT_TYPES, "application/octet-stream", "application/gzip", "application/x-gzip",
     "text/plain", "text/tab-separated-values"}
)
_FORM_FIELDS = ("file", "metadata", "format", "channel_map")
_UPLOAD_NAME = "upload"


@dataclass
class _Received:
    path: Path
    sha256: str
    size: int
    filename: str | None = None
    content_type: str | None = None
    fields: dict[str, str] = field(default_factory=dict)


class _Sink:
    """Capped, hashing file writer fed with blocks of the body.

    Before each block is written the free space is checked: writing it must
    leave ``reserve`` bytes free (:class:`DiskFullError` otherwise).
    """

    def __init__(self, path: Path, block_bytes: int, reserve: int) -> None:
        self.path = path
        self.block_bytes = block_bytes
        self.reserve = reserve
        self.hash = hashlib.sha256()
        self.size = 0
        self._buffer = bytearray()
        self._fh = open(path, "wb", buffering=0)  # noqa: SIM115 - closed in close()

    def _write(self, data: bytes) -> None:
        require_free(self.path.parent, len(data), self.reserve, "the upload")
        self.hash.update(data)
        self._fh.write(data)

    async def feed(self, data: bytes) -> None:
        self.size += len(data)
        self._buffer += data
        if len(self._buffer) >= self.block_bytes:
            block, self._buffer = bytes(self._buffer), bytearray()
            await run_in_threadpool(self._write, block)

    async def close(self) -> None:
        if self._buffer:
            block, self._buffer = bytes(self._buffer), bytearray()
            await run_in_threadpool(self._write, block)
        self._fh.close()

    def abort(self) -> None:
        self._fh.close()


def _too_large(cap: int) -> ApiError:
    return ApiError(
        413, "file", f"upload exceeds the size limit of {cap} bytes (TRACKVKF_MAX_UPLOAD_BYTES)"
    )


def _storage_full(exc: BaseException) -> ApiError:
    reason = str(exc) if isinstance(exc, DiskFullError) else "the run store or the database is full"
    return ApiError(507, "storage", f"{reason}; the upload was not kept, free space and try again")


def _unsupported_type(ctype: str) -> ApiError:
    return ApiError(
        415,
        "content_type",
        f"unsupported content type {ctype[:80]!r}; send a run file as "
        "application/octet-stream, application/x-hdf5, text/csv or application/vnd.apache.parquet",
    )


def _safe_filename(name: str | None) -> str | None:
    """Keep only the last path component of a client file name (stored as text only)."""
    if not name:
        return None
    name = name.replace("\\", "/").rsplit("/", 1)[-1].strip()
    name = "".join(ch for ch in name if ch.isprintable())
    return name[:255] or None


async def _receive_raw(request: Request, path: Path, settings: Settings) -> _Received:
    sink = _Sink(path, settings.upload_block_bytes, settings.min_free_bytes)
    try:
        async for chunk in request.stream():
            if sink.size + len(chunk) > settings.max_upload_bytes:
                raise _too_large(settings.max_upload_bytes)
            await sink.feed(chunk)
        await sink.close()
    except BaseException:
        sink.abort()
        raise
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower() or None
    return _Received(path=path, sha256=sink.hash.hexdigest(), size=sink.size, content_type=ctype)


class _MultipartState:
    """Collects the events of the synchronous multipart parser."""

    def __init__(self, max_field_bytes: int) -> None:
        self.max_field_bytes = max_field_bytes
        self.header_field = bytearray()
        self.header_value = bytearray()
        self.headers: dict[str, str] = {}
        self.name: str | None = None
        self.is_file = False
        self.file_seen = False
        self.filename: str | None = None
        self.file_content_type: str | None = None
        self.field_data = bytearray()
        self.fields: dict[str, str] = {}
        self.pending_file_data: list[bytes] = []
        self.error: ApiError | None = None
        self.ended = False

    def callbacks(self) -> dict[str, Any]:
        return {
            "on_part_begin": self.on_part_begin,
            "on_header_field": self.on_header_field,
            "on_header_value": self.on_header_value,
            "on_header_end": self.on_header_end,
            "on_headers_finished": self.on_headers_finished,
            "on_part_data": self.on_part_data,
            "on_part_end": self.on_part_end,
            "on_end": self.on_end,
        }

    def on_part_begin(self) -> None:
        self.headers = {}
        self.name = None
        self.is_file = False
        self.field_data = bytearray()

    def on_header_field(self, data: bytes, start: int, end: int) -> None:
        self.header_field += data[start:end]

    def on_header_value(self, data: bytes, start: int, end: int) -> None:
        self.header_value += data[start:end]

    def on_header_end(self) -> None:
        self.headers[self.header_field.decode("latin-1").lower()] = self.header_value.decode(
            "latin-1"
        )
        self.header_field = bytearray()
        self.header_value = bytearray()

    def on_headers_finished(self) -> None:
        _, options = parse_options_header(self.headers.get("content-disposition"))
        name = options.get(b"name", b"").decode("utf-8", "replace")
        if name not in _FORM_FIELDS:
            self.error = self.error or ApiError(
                422, "form",
                f"unknown form field {name!r} (expected file, metadata, format or channel_map)",
            )
        self.name = name
        if name == "file":
            if self.file_seen:
                self.error = self.error or ApiError(422, "file", "more than one file part")
            self.file_seen = True
            self.is_file = True
            raw = options.get(b"filename")
            self.filename = _safe_filename(raw.decode("utf-8", "replace")) if raw else None
            ctype = self.headers.get("content-type")
            self.file_content_type = ctype.split(";")[0].strip().lower() if ctype else None
            if self.file_content_type and self.file_content_type not in ACCEPTED_CONTENT_TYPES:
                self.error = self.error or _unsupported_type(self.file_content_type)

    def on_part_data(self, data: bytes, start: int, end: int) -> None:
        if self.error is not None:
            return
        if self.is_file:
            self.pending_file_data.append(bytes(data[start:end]))
        else:
            self.field_data += data[start:end]
            if len(self.field_data) > self.max_field_bytes:
                self.error = ApiError(
                    413, self.name or "form", f"form field larger than {self.max_field_bytes} bytes"
                )

    def on_part_end(self) -> None:
        if self.error is None and not self.is_file and self.name:
            if self.name in self.fields:
                self.error = ApiError(422, self.name, "given more than once")
                return
            try:
                self.fields[self.name] = self.field_data.decode("utf-8")
            except UnicodeDecodeError:
                self.error = ApiError(422, self.name, "not valid UTF-8 text")

    def on_end(self) -> None:
        self.ended = True


async def _receive_multipart(
    request: Request, path: Path, settings: Settings, content_type: str
) -> _Received:
    _, params = parse_options_header(content_type)
    boundary = params.get(b"boundary")
    if not boundary:
        raise ApiError(400, "file", "multipart body without a boundary in Content-Type")
    state = _MultipartState(settings.max_metadata_bytes)
    try:
        parser = MultipartParser(boundary, state.callbacks())
    except FormParserError as exc:
        raise ApiError(400, "file", f"malformed multipart body: {exc}") from None
    sink = _Sink(path, settings.upload_block_bytes, settings.min_free_bytes)
    received = 0
    try:
        async for chunk in request.stream():
            received += len(chunk)
            if received > settings.max_upload_bytes:
                raise _too_large(settings.max_upload_bytes)
            try:
                parser.write(chunk)
            except FormParserError as exc:
                raise ApiError(400, "file", f"malformed multipart body: {exc}") from None
            if state.error is not None:
                raise state.error
            for data in state.pending_file_data:
                await sink.feed(data)
            state.pending_file_data.clear()
        try:
            parser.finalize()
        except FormParserError as exc:
            raise ApiError(400, "file", f"malformed multipart body: {exc}") from None
        if state.error is not None:
            raise state.error
        await sink.close()
    except BaseException:
        sink.abort()
        raise
    if not state.file_seen:
        raise ApiError(422, "file", "the multipart body has no 'file' part")
    if not state.ended:
        raise ApiError(400, "file", "multipart body ended early (truncated upload)")
    return _Received(
        path=path,
        sha256=sink.hash.hexdigest(),
        size=sink.size,
        filename=state.filename,
        content_type=state.file_content_type,
        fields=state.fields,
    )


def _known_suffix(filename: str | None) -> str:
    """The file name's extension if it is a known run-file extension, else ``""``."""
    if not filename:
        return ""
    name = filename.lower()
    for suffix in sorted(_EXTENSIONS, key=len, reverse=True):
        if name.endswith(suffix):
            return suffix
    return ""


def infer_format(
    explicit: str | None, filename: str | None, content_type: str | None
) -> str | None:
    """The upload's format: explicit value, else file extension, else content type.

    Returns None when nothing tells (ingest then inspects the file).

    Raises
    ------
    ApiError
        422 naming ``format`` if ``explicit`` is not a supported format.
    """
    if explicit:
        key = explicit.strip().lower()
        if key not in _FORMAT_ALIASES:
            raise ApiError(
                422,
                "format",
                f"unknown format {explicit!r}; supported formats are {', '.join(SUPPORTED_FORMATS)}",
            )
        return _FORMAT_ALIASES[key]
    suffix = _known_suffix(filename)
    if suffix:
        return _EXTENSIONS[suffix]
    if content_type and content_type in _CONTENT_TYPES:
        return _CONTENT_TYPES[content_type]
    return None


def _parse_metadata(text: str | None) -> dict[str, Any] | None:
    if text is None or not text.strip():
        return None
    return load_metadata_json(text, field="metadata")  # RunFileError: 422 naming the field


def _one_of(name: str, form_value: str | None, query_value: str | None) -> str | None:
    if form_value is not None and query_value is not None:
        raise ApiError(422, name, "given both as form field and as query parameter")
    return form_value if form_value is not None else query_value


async def receive_and_create_run(
    request: Request,
    *,
    settings: Settings,
    db: Database,
    store: RunStore,
    actor: Actor,
    query_format: str | None = None,
    query_metadata: str | None = None,
    query_filename: str | None = None,
    query_channel_map: str | None = None,
) -> UploadOutcome:
    """Receive an upload, validate it and create the run and its processing job.

    Returns
    -------
    UploadOutcome
        The new run (``created=True``) or the existing run with the same
        sha256 (``created=False``).

    Raises
    ------
    ApiError
        429 over the upload rate of the principal, 413 for a body over the
        cap, 415 for a content type that is not a run file's, 400 for a
        malformed body, 422 naming the field for invalid content (format,
        metadata, channels, ...), 507 (``storage``) when the run store (or the
        database) has not enough free space. Nothing is left behind but the
        audit entry of the rejection.
    """
    key_id = actor.principal.key_id if actor.principal is not None else None
    wait = request.app.state.upload_limiter.hit(f"key:{key_id}" if key_id is not None else f"user:{actor.name}")
    if wait is not None:
        seconds = max(1, int(wait + 0.999))
        error = ApiError(
            429, "rate_limit", f"too many uploads; retry in {seconds} s", {"Retry-After": str(seconds)}
        )
        await run_in_threadpool(_record_rejection, db, actor, error, "denied")
        raise error
    try:
        try:
            return await _receive_and_create(
                request, settings=settings, db=db, store=store, actor=actor,
                query_format=query_format, query_metadata=query_metadata, query_filename=query_filename,
                query_channel_map=query_channel_map,
            )
        except Exception as exc:
            if not isinstance(exc, ApiError) and is_disk_full(exc):
                log.warning("upload refused: %s", exc)
                raise _storage_full(exc) from None
            raise
    except (ApiError, RunFileError) as exc:
        rejection = exc if isinstance(exc, ApiError) else run_file_error(exc)
        await run_in_threadpool(_record_rejection, db, actor, rejection, "rejected")
        raise
    except Exception as exc:
        # not the client's fault (a bug, the database away): answered 500, audited all the same
        error = ApiError(500, "server", f"{type(exc).__name__}: {exc}")
        await run_in_threadpool(_record_rejection, db, actor, error, "error")
        raise


def _record_rejection(db: Database, actor: Actor, exc: ApiError, outcome: str) -> None:
    try:
        record_now(db, actor, "run.upload", outcome=outcome, detail={
            "status": exc.status_code, "field": exc.field, "message": exc.message[:500],
        })
    except Exception:  # noqa: BLE001 - the client gets the rejection; the failure is logged
        log.exception("could not write the audit entry of a rejected upload")


async def _receive_and_create(
    request: Request,
    *,
    settings: Settings,
    db: Database,
    store: RunStore,
    actor: Actor,
    query_format: str | None,
    query_metadata: str | None,
    query_filename: str | None,
    query_channel_map: str | None,
) -> UploadOutcome:
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > settings.max_upload_bytes:
        raise _too_large(settings.max_upload_bytes)
    if declared is not None and declared.isdigit():
        await run_in_threadpool(require_free, store.root, int(declared), settings.min_free_bytes, "the upload")
    content_type = request.headers.get("content-type", "")
    bare_type = content_type.split(";")[0].strip().lower()
    if bare_type and bare_type != "multipart/form-data" and bare_type not in ACCEPTED_CONTENT_TYPES:
        raise _unsupported_type(bare_type)
    with store.upload_dir() as upload_dir:
        path = upload_dir / _UPLOAD_NAME
        try:
            if content_type.lower().startswith("multipart/form-data"):
                received = await _receive_multipart(request, path, settings, content_type)
            else:
                received = await _receive_raw(request, path, settings)
                received.filename = _safe_filename(query_filename)
        except ClientDisconnect:
            raise ApiError(400, "file", "client disconnected during the upload") from None
        if received.size == 0:
            raise ApiError(422, "file", "the uploaded file is empty")
        # A known extension helps ingest recognise e.g. gzip-compressed CSV.
        suffix = _known_suffix(received.filename)
        if suffix:
            path = path.rename(upload_dir / f"upload{suffix}")
            received.path = path
        fmt = infer_format(
            _one_of("format", received.fields.get("format"), query_format),
            received.filename,
            received.content_type,
        )
        metadata = _parse_metadata(_one_of("metadata", received.fields.get("metadata"), query_metadata))

        file = UploadedFile(path, received.sha256, received.size, received.filename)
        existing = await run_in_threadpool(existing_outcome, db, file.sha256, metadata)
        if existing is not None:
            return existing
        # ingest and create: a few at a time per process, so reads keep their share (issue 24)
        return await run_heavy(
            request.app,
            lambda: create_run_from_file(
                db, store, upload_dir, file, fmt=fmt, metadata=metadata,
                channel_map=_one_of("channel_map", received.fields.get("channel_map"), query_channel_map),
                actor=actor, settings=settings,
            ),
        )
