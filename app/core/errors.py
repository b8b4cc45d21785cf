"""The error a request is answered with: a status, the field at fault and a message.

:class:`ApiError` is raised by the routes and by the services they call (a service
knows best which parameter a request got wrong); the API renders every one as
``{"detail": "<field>: <message>", "field": "<field>"}`` (:mod:`app.api.errors`).
"""

from __future__ import annotations

from app.core.i18n import N_, Msg, translate

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
        Human-readable explanation; cut to :data:`MAX_MESSAGE_CHARS` characters. A
        :class:`~app.core.i18n.Msg` (``_("...")``) is answered in the request's language.
    headers : dict, optional
        Extra response headers (``WWW-Authenticate``, ``Retry-After``).
    """

    def __init__(
        self, status_code: int, field: str, message: str, headers: dict[str, str] | None = None
    ) -> None:
        self.status_code = status_code
        self.field = cut_message(str(field), 200)
        self.message = cut_message(str(message))
        self.source = message if isinstance(message, Msg) else None
        self.headers = headers
        super().__init__(f"{self.field}: {self.message}")

    def message_in(self, lang: str) -> str:
        """The message in ``lang`` (a message not marked for translation: as it is)."""
        return self.message if self.source is None else cut_message(translate(self.source, lang))


#: the 404 message of each kind of thing (the thing's name translated with it)
_NOT_FOUND: dict[str, str] = {
    "run": N_("run {ident} not found"),
    "job": N_("job {ident} not found"),
    "place": N_("place {ident} not found"),
    "geometry": N_("geometry {ident} not found"),
    "action": N_("maintenance action {ident} not found"),
    "asset": N_("asset {ident} not found"),
    "channel_map": N_("channel map {ident} not found"),
    "webhook": N_("webhook {ident} not found"),
}
_NOT_FOUND_ANY = N_("{what} {ident} not found")


def not_found(what: str, ident: object) -> ApiError:
    """A 404 error for ``what`` (``"run"``, ``"job"``) with id ``ident``."""
    return ApiError(404, f"{what}_id", Msg(_NOT_FOUND.get(what, _NOT_FOUND_ANY), what=what, ident=ident))
