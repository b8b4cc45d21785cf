"""Error responses of the API: ``{"detail": "<field>: <message>", "field": "<field>"}``."""

from __future__ import annotations

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

__all__ = ["ApiError", "not_found", "install_error_handlers"]


class ApiError(Exception):
    """An error answered with ``status_code`` and a message naming the problem.

    Parameters
    ----------
    status_code : int
        HTTP status (4xx).
    field : str
        What is wrong: a channel, a metadata field, a query parameter,
        ``format``, ``file`` ...
    message : str
        Human-readable explanation.
    headers : dict, optional
        Extra response headers (``WWW-Authenticate``, ``Retry-After``).
    """

    def __init__(
        self, status_code: int, field: str, message: str, headers: dict[str, str] | None = None
    ) -> None:
        super().__init__(f"{field}: {message}")
        self.status_code = status_code
        self.field = field
        self.message = message
        self.headers = headers


def not_found(what: str, ident: object) -> ApiError:
    """A 404 error for ``what`` (``"run"``, ``"job"``) with id ``ident``."""
    return ApiError(404, f"{what}_id", f"{what} {ident} not found")


async def _api_error_handler(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, ApiError)
    return JSONResponse(
        status_code=exc.status_code,
        content={"detail": f"{exc.field}: {exc.message}", "field": exc.field},
        headers=exc.headers,
    )


def install_error_handlers(app: FastAPI) -> None:
    """Register the handler that renders :class:`ApiError`."""
    app.add_exception_handler(ApiError, _api_error_handler)
