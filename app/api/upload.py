"""Streamed run uploads: the request body received into the run store (sha256, size cap,
multipart parsing), then handed to the run service.

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
in memory whole. What the service decides of the received file (its format and
metadata, the upload rate, how a refusal is answered and audited) is
:mod:`app.runs.upload`; the run is made by
:func:`app.runs.create.create_run_from_file`: validated and converted by
:func:`app.io.ingest` to the canonical HDF5 file, and only then are the run
row and its processing job inserted and the directory moved to its final
place. Any failure removes the upload directory: no row, job or file remains.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from python_multipart.exceptions import FormParserError
from python_multipart.multipart import MultipartParser, parse_options_header
from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect, Request

from app.api.deps import Actor
from app.api.errors import ApiError
from app.core.diskspace import require_free
from app.core.i18n import _
from app.core.runstore import RunStore
from app.db.session import Database
from app.io.formats import CONTENT_TYPE_FORMATS
from app.operations.heavy import run_heavy
from app.runs import upload as uploads
from app.runs.create import UploadOutcome, create_run_from_file, existing_outcome
from app.runs.upload import Received
from app.settings import Settings

__all__ = ["UploadOutcome", "receive_and_create_run", "ACCEPTED_CONTENT_TYPES"]

#: Content types accepted for a raw body or a multipart file part (besides none at all).
ACCEPTED_CONTENT_TYPES: frozenset[str] = frozenset(
    {*CONTENT_TYPE_FORMATS, "application/octet-stream", "application/gzip", "application/x-gzip",
     "text/plain", "text/tab-separated-values"}
)
_FORM_FIELDS = ("file", "metadata", "format", "channel_map")
_UPLOAD_NAME = "upload"


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
        require_free(self.path.parent, len(data), self.reserve, _("the upload"))
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
        413, "file", _("upload exceeds the size limit of {cap} bytes (TRACKVKF_MAX_UPLOAD_BYTES)", cap=cap)
    )


def _unsupported_type(ctype: str) -> ApiError:
    return ApiError(
        415,
        "content_type",
        _("unsupported content type {ctype}; send a run file as application/octet-stream, application/x-hdf5, "
          "text/csv or application/vnd.apache.parquet", ctype=repr(ctype[:80])),
    )


def _safe_filename(name: str | None) -> str | None:
    """Keep only the last path component of a client file name (stored as text only)."""
    if not name:
        return None
    name = name.replace("\\", "/").rsplit("/", 1)[-1].strip()
    name = "".join(ch for ch in name if ch.isprintable())
    return name[:255] or None


async def _receive_raw(request: Request, path: Path, settings: Settings) -> Received:
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
    return Received(path=path, sha256=sink.hash.hexdigest(), size=sink.size, content_type=ctype)


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
        _kind, options = parse_options_header(self.headers.get("content-disposition"))
        name = options.get(b"name", b"").decode("utf-8", "replace")
        if name not in _FORM_FIELDS:
            self.error = self.error or ApiError(
                422, "form",
                _("unknown form field {name} (expected file, metadata, format or channel_map)", name=repr(name)),
            )
        self.name = name
        if name == "file":
            if self.file_seen:
                self.error = self.error or ApiError(422, "file", _("more than one file part"))
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
                    413, self.name or "form", _("form field larger than {max_field_bytes} bytes", max_field_bytes=self.max_field_bytes)
                )

    def on_part_end(self) -> None:
        if self.error is None and not self.is_file and self.name:
            if self.name in self.fields:
                self.error = ApiError(422, self.name, _("given more than once"))
                return
            try:
                self.fields[self.name] = self.field_data.decode("utf-8")
            except UnicodeDecodeError:
                self.error = ApiError(422, self.name, _("not valid UTF-8 text"))

    def on_end(self) -> None:
        self.ended = True


async def _receive_multipart(
    request: Request, path: Path, settings: Settings, content_type: str
) -> Received:
    _kind, params = parse_options_header(content_type)
    boundary = params.get(b"boundary")
    if not boundary:
        raise ApiError(400, "file", _("multipart body without a boundary in Content-Type"))
    state = _MultipartState(settings.max_metadata_bytes)
    try:
        parser = MultipartParser(boundary, state.callbacks())
    except FormParserError as exc:
        raise ApiError(400, "file", _("malformed multipart body: {exc}", exc=exc)) from None
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
                raise ApiError(400, "file", _("malformed multipart body: {exc}", exc=exc)) from None
            if state.error is not None:
                raise state.error
            for data in state.pending_file_data:
                await sink.feed(data)
            state.pending_file_data.clear()
        try:
            parser.finalize()
        except FormParserError as exc:
            raise ApiError(400, "file", _("malformed multipart body: {exc}", exc=exc)) from None
        if state.error is not None:
            raise state.error
        await sink.close()
    except BaseException:
        sink.abort()
        raise
    if not state.file_seen:
        raise ApiError(422, "file", _("the multipart body has no 'file' part"))
    if not state.ended:
        raise ApiError(400, "file", _("multipart body ended early (truncated upload)"))
    return Received(
        path=path,
        sha256=sink.hash.hexdigest(),
        size=sink.size,
        filename=state.filename,
        content_type=state.file_content_type,
        fields=state.fields,
    )


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
        audit entry of the refusal (:func:`app.runs.upload.refusal`).
    """
    wait = request.app.state.upload_limiter.hit(uploads.rate_key(actor))
    if wait is not None:
        error = uploads.too_many_uploads(wait)
        await run_in_threadpool(uploads.record_refusal, db, actor, error, "denied")
        raise error
    try:
        return await _receive_and_create(
            request, settings=settings, db=db, store=store, actor=actor,
            query_format=query_format, query_metadata=query_metadata, query_filename=query_filename,
            query_channel_map=query_channel_map,
        )
    except Exception as exc:
        error, outcome, instead = uploads.refusal(exc)
        await run_in_threadpool(uploads.record_refusal, db, actor, error, outcome)
        if instead is not None:
            raise instead from None
        raise


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
            raise ApiError(400, "file", _("client disconnected during the upload")) from None
        upload = uploads.upload_of(received, query_format=query_format, query_metadata=query_metadata,
                                   query_channel_map=query_channel_map)
        existing = await run_in_threadpool(existing_outcome, db, upload.file.sha256, upload.metadata)
        if existing is not None:
            return existing
        # ingest and create: a few at a time per process, so reads keep their share (issue 24)
        return await run_heavy(
            request.app,
            lambda: create_run_from_file(
                db, store, upload_dir, upload.file, fmt=upload.fmt, metadata=upload.metadata,
                channel_map=upload.channel_map, actor=actor, settings=settings,
            ),
        )
