"""The error a request is answered with: a status, the field at fault and a message.

:class:`ApiError` is raised by the routes and by the services they call (a service
knows best which parameter a request got wrong); the API renders every one as
``{"detail": "<field>: <message>", "field": "<field>"}`` (:mod:`app.api.errors`).
"""

from __future__ import annotations

__all__ = ["ApiError", "MAX_MESSAGE_CHARS", "cut_message", "not_found"]

#: Longest message of an error answer, characters (longer ones are cut, ending in "…").
MAX_MESSAGE_CHARS = 500


def cut_message(text: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``text``, cut to ``limit`` characters (ending in "…" when cut): no answer echoes a large input."""
    return text if len(text) <= limit else text[: limit - 1] + "…"


class ApiError(Exception):
    """An error answered with ``status_code`` and a message naming the problem.

    Parameters
    ----------
    status_code : int
        HTTP status (4xx; 507 when the run store is full).
    field : str
        What is wrong: a channel, a metadata field, a query parameter,
        ``format``, ``file`` ...
    message : str
        Human-readable explanation; cut to :data:`MAX_MESSAGE_CHARS` characters.
    headers : dict, optional
        Extra response headers (``WWW-Authenticate``, ``Retry-After``).
    """

    def __init__(
        self, status_code: int, field: str, message: str, headers: dict[str, str] | None = None
    ) -> None:
        self.status_code = status_code
        self.field = cut_message(str(field), 200)
        self.message = cut_message(str(message))
        self.headers = headers
        super().__init__(f"{self.field}: {self.message}")


def not_found(what: str, ident: object) -> ApiError:
    """A 404 error for ``what`` (``"run"``, ``"job"``) with id ``ident``."""
    return ApiError(404, f"{what}_id", f"{what} {ident} not found")
