"""Error responses of the API: ``{"detail": "<field>: <message>", "field": "<field>"}``.

Every error the API answers takes this form: :class:`~app.core.errors.ApiError` raised by the
routes, their dependencies and the services they call, :class:`~app.io.RunFileError` (a run
or reference file, metadata or channel map that is not valid: 422 naming the field,
:func:`run_file_error`), FastAPI's own validation of query, path and body parameters
(:class:`fastapi.exceptions.RequestValidationError`), whose list of problems is reduced to
the first one, naming its parameter, Starlette's HTTP errors (unknown path → ``path``,
method → ``method``, a body that cannot be parsed → ``body``), PostgreSQL's refusal of NUL
characters in text (a query filter holding one), the database's write lock busy past
``TRACKVKF_DB_LOCK_WAIT_S`` (503 ``database`` with ``Retry-After``) and, last, any exception a route did not
expect: answered ``500`` with ``"field": "server"`` (its traceback goes to the log, never to
the client) by :class:`CatchAllMiddleware`, on a connection that stays open. Messages are
cut to :data:`MAX_MESSAGE_CHARS`: no answer echoes a large input.

The message is in the request's language (:func:`app.api.language.request_language`) where it
was marked for translation (``_("...")``, :class:`~app.core.i18n.Msg`), pydantic's wording of
the common validation errors included; ``field`` and the part of ``detail`` before the colon
stay as they are: what a program reads of an error does not change with the language.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import DataError, OperationalError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.api.language import request_language
from app.core.errors import MAX_MESSAGE_CHARS, ApiError, cut_message, not_found, pydantic_message
from app.core.i18n import _
from app.io import RunFileError

__all__ = [
    "ApiError",
    "MAX_MESSAGE_CHARS",
    "ERROR_SCHEMA",
    "not_found",
    "run_file_error",
    "validation_error",
    "document_error_responses",
    "install_error_handlers",
    "CatchAllMiddleware",
    "INTERNAL_ERROR",
]

log = logging.getLogger(__name__)

#: OpenAPI schema of an error answer.
ERROR_SCHEMA: dict[str, Any] = {
    "title": "ApiError",
    "type": "object",
    "required": ["detail", "field"],
    "properties": {
        "detail": {"type": "string", "description": "<field>: <message>"},
        "field": {"type": "string", "description": "The field, parameter or part at fault"},
    },
}

_PARAMETER_KINDS = ("query", "path", "body", "header", "cookie")

#: The answer to an exception no route expected (the details are in the service log).
INTERNAL_ERROR: dict[str, str] = {"detail": "server: internal error (logged on the server)", "field": "server"}
_INTERNAL_MESSAGE = _("internal error (logged on the server)")
#: Starlette's message when the body is not JSON it can parse (too deep, a number too long …).
_BODY_PARSE_ERROR = "There was an error parsing the body"


def _shown(value: Any) -> str:
    return cut_message(repr(value), 60)


def validation_error(errors: Sequence[dict[str, Any]]) -> ApiError:
    """The 422 :class:`ApiError` of FastAPI's (pydantic's) list of validation errors.

    The first error names the field: its location without the parameter kind
    (``("query", "limit")`` → ``limit``, ``("body", "a", 0)`` → ``a.0``), its
    message and, unless missing, the value given (cut short). Further errors
    (up to three) follow in the message as ``also <field>: <message>``, so that
    a body with a misspelt key says both what is missing and what is unknown.
    """
    if not errors:
        return ApiError(422, "request", _("invalid request"))
    field, message = _described(errors[0])
    for i, err in enumerate(errors[1:4]):
        other, text = _described(err)
        also = _("{message}; also {field}: {problem}", message=message, field=other, problem=text)
        message = also if i == 0 else _("{message}; {field}: {problem}", message=message, field=other, problem=text)
    return ApiError(422, field, message)


def _described(err: dict[str, Any]) -> tuple[str, str]:
    """(field, message) of one pydantic validation error."""
    loc = [str(p) for p in err.get("loc", ())]
    kind = err.get("type", "")
    if loc and loc[0] in _PARAMETER_KINDS:
        place, rest = loc[0], loc[1:]
    else:
        place, rest = "request", loc
    if kind == "json_invalid":
        reason = (err.get("ctx") or {}).get("error")
        return place, _("not valid JSON: {reason}", reason=reason) if reason else _("not valid JSON")
    field = ".".join(rest) or place
    message = pydantic_message(err)
    if kind == "missing":
        message = _("required")
    elif "input" in err:
        message = _("{message} (got {value})", message=message, value=_shown(err["input"]))
    return field, message


async def _api_error_handler(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, ApiError)
    message = exc.message_in(request_language(request).code)
    return JSONResponse(
        status_code=exc.status_code,
        content={"detail": f"{exc.field}: {message}", "field": exc.field},
        headers=exc.headers,
    )


def run_file_error(exc: RunFileError) -> ApiError:
    """The 422 of an invalid file, metadata or channel map, naming its field (the one mapping)."""
    return ApiError(422, exc.field, exc.message)


async def _run_file_error_handler(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RunFileError)
    return await _api_error_handler(request, run_file_error(exc))


async def _validation_error_handler(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError)
    return await _api_error_handler(request, validation_error(exc.errors()))


async def _data_error_handler(request: Request, exc: Exception) -> JSONResponse:
    """PostgreSQL refuses NUL characters in text: the client's input, answered 422 naming it."""
    assert isinstance(exc, DataError)
    if "NUL" not in str(exc.orig):
        raise exc
    field = next((k for k, v in request.query_params.multi_items() if "\x00" in k or "\x00" in v), "request")
    return await _api_error_handler(
        request, ApiError(422, field, _("text must not contain NUL characters (\\u0000)"))
    )


#: seconds a client is asked to wait after the database's write lock was busy past the deadline
LOCK_RETRY_AFTER_S = 2


def is_lock_timeout(exc: BaseException) -> bool:
    """Whether a database error is a write lock not obtained within the deadline (SQLite ``database is
    locked``/``busy``; PostgreSQL ``lock_not_available``, 55P03)."""
    orig = getattr(exc, "orig", None)
    text = str(orig if orig is not None else exc).lower()
    return ("database is locked" in text or "database table is locked" in text or "database is busy" in text
            or getattr(orig, "sqlstate", None) == "55P03")


async def _operational_error_handler(request: Request, exc: Exception) -> JSONResponse:
    """The write lock not obtained within ``TRACKVKF_DB_LOCK_WAIT_S`` (the driver retried until then):
    503 with ``Retry-After``, the request changed nothing. Any other operational error is unexpected."""
    assert isinstance(exc, OperationalError)
    if not is_lock_timeout(exc):
        raise exc
    log.warning("%s %s: the database's write lock stayed busy past the deadline (503)", request.method,
                request.url.path)
    return await _api_error_handler(request, ApiError(
        503, "database", _("busy with another write; nothing was changed, retry in {seconds} s", seconds=LOCK_RETRY_AFTER_S),
        {"Retry-After": str(LOCK_RETRY_AFTER_S)}))


async def _http_error_handler(request: Request, exc: Exception) -> Any:
    """Starlette's HTTP errors (404, 405, 400 of body parsing …) in the project's error shape."""
    assert isinstance(exc, StarletteHTTPException)
    if exc.status_code < 400:  # the pages' redirect to the login page
        return await http_exception_handler(request, exc)
    detail = str(exc.detail)
    message: str
    if exc.status_code == 404 and detail == "Not Found":
        field, message = "path", _("no such path {path}", path=repr(request.url.path[:200]))
    elif exc.status_code == 405:
        field, message = "method", _("{method} is not allowed here", method=request.method)
    elif exc.status_code == 400 and detail == _BODY_PARSE_ERROR:
        field, message = "body", _(
            "cannot be parsed as JSON (nested too deeply or a number with too many digits?)"
        )
    else:
        field, message = "request", detail
    return await _api_error_handler(request, ApiError(exc.status_code, field, message, exc.headers))


def _internal_error(scope: Scope) -> JSONResponse:
    """The 500 answer, in the language of the request's browser."""
    lang = request_language(Request(scope)).code
    return JSONResponse(status_code=500, content={
        "detail": f"server: {_INTERNAL_MESSAGE.in_language(lang)}", "field": "server"})


async def _unexpected_error_handler(request: Request, exc: Exception) -> JSONResponse:
    """Last resort of Starlette's outermost middleware (an error raised by a middleware itself)."""
    return _internal_error(request.scope)


class CatchAllMiddleware:
    """An exception no route expected: logged, answered 500 in the error shape, connection kept.

    Starlette's own last resort answers and then re-raises the exception to the
    server, which closes the keep-alive connection after any 500. This ASGI
    middleware sits inside the other middlewares (the answer still gets the
    security headers) and ends the request there instead. An exception after
    the answer has started cannot be answered any more: it is re-raised.
    """

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def tracked(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, receive, tracked)
        except Exception:
            log.exception("unexpected error answering %s %s", scope.get("method"), scope.get("path"))
            if started:
                raise
            await _internal_error(scope)(scope, receive, send)


def document_error_responses(schema: dict[str, Any]) -> dict[str, Any]:
    """Make an OpenAPI schema say what the API answers on errors: :data:`ERROR_SCHEMA`.

    FastAPI documents its validation errors as ``HTTPValidationError`` (a
    list); the handler installed by :func:`install_error_handlers` answers
    them as every other error, so each 422 refers to ``ApiError`` and the
    list schemas are dropped.
    """
    schemas = schema.setdefault("components", {}).setdefault("schemas", {})
    schemas["ApiError"] = ERROR_SCHEMA
    for name in ("HTTPValidationError", "ValidationError"):
        schemas.pop(name, None)
    for operations in schema.get("paths", {}).values():
        for operation in operations.values():
            if not isinstance(operation, dict):
                continue
            response = operation.get("responses", {}).get("422")
            if response is not None:
                content = response.setdefault("content", {}).setdefault("application/json", {})
                content["schema"] = {"$ref": "#/components/schemas/ApiError"}
    return schema


def install_error_handlers(app: FastAPI) -> None:
    """Register the handlers of every error (call before adding the other middlewares)."""
    app.add_exception_handler(ApiError, _api_error_handler)
    app.add_exception_handler(RunFileError, _run_file_error_handler)
    app.add_exception_handler(RequestValidationError, _validation_error_handler)
    app.add_exception_handler(DataError, _data_error_handler)
    app.add_exception_handler(OperationalError, _operational_error_handler)
    app.add_exception_handler(StarletteHTTPException, _http_error_handler)
    app.add_exception_handler(Exception, _unexpected_error_handler)
    app.add_middleware(CatchAllMiddleware)
