"""The error a request is answered with: a status, the field at fault and a message.

:class:`ApiError` is raised by the routes and by the services they call (a service
knows best which parameter a request got wrong); the API renders every one as
``{"detail": "<field>: <message>", "field": "<field>"}`` (:mod:`app.api.errors`).
"""

from __future__ import annotations

from typing import Any

from app.core.i18n import N_, Msg, _, translate

__all__ = ["ApiError", "MAX_MESSAGE_CHARS", "PYDANTIC_MESSAGES", "cut_message", "not_found", "pydantic_message"]

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


#: pydantic's validation errors, by type, in words of ours (other languages; English keeps
#: pydantic's own): the message id and the context values it names
PYDANTIC_MESSAGES: dict[str, str] = {
    "greater_than": N_("must be greater than {gt}"),
    "greater_than_equal": N_("must be greater than or equal to {ge}"),
    "less_than": N_("must be less than {lt}"),
    "less_than_equal": N_("must be less than or equal to {le}"),
    "int_parsing": N_("must be a whole number"),
    "int_type": N_("must be a whole number"),
    "int_from_float": N_("must be a whole number"),
    "float_parsing": N_("must be a number"),
    "float_type": N_("must be a number"),
    "finite_number": N_("must be a finite number"),
    "bool_parsing": N_("must be true or false"),
    "bool_type": N_("must be true or false"),
    "string_type": N_("must be text"),
    "string_too_long": N_("must have at most {max_length} characters"),
    "string_too_short": N_("must have at least {min_length} characters"),
    "string_pattern_mismatch": N_("does not have the expected form"),
    "literal_error": N_("must be one of {expected}"),
    "enum": N_("must be one of {expected}"),
    "extra_forbidden": N_("is not a field of this request"),
    "too_long": N_("has too many items"),
    "too_short": N_("has too few items"),
    "date_parsing": N_("must be a date (YYYY-MM-DD)"),
    "date_from_datetime_parsing": N_("must be a date (YYYY-MM-DD)"),
    "datetime_parsing": N_("must be a date and time (ISO 8601)"),
    "datetime_from_date_parsing": N_("must be a date and time (ISO 8601)"),
    "url_parsing": N_("must be a URL"),
    "url_scheme": N_("must be a URL"),
    "dict_type": N_("must be an object"),
    "list_type": N_("must be a list"),
}


def pydantic_message(err: dict[str, Any]) -> str:
    """pydantic's message of ``err`` (an entry of ``ValidationError.errors()``), translatable where its
    type is one of :data:`PYDANTIC_MESSAGES`; a validator's own ``ValueError(_("..."))`` keeps its message."""
    if err.get("type") == "value_error":
        error = (err.get("ctx") or {}).get("error")
        field, message = getattr(error, "field", None), getattr(error, "message", None)
        if isinstance(field, str) and isinstance(message, Msg):  # a RunFileError raised in a validator
            return _("{field}: {problem}", field=field, problem=message)
        if isinstance(error, Exception) and error.args and isinstance(error.args[0], Msg):
            return error.args[0]
    english = str(err.get("msg", "invalid value")).removeprefix("Value error, ")
    msgid = PYDANTIC_MESSAGES.get(str(err.get("type", "")))
    if msgid is None:
        return english
    ctx = {k: str(v) for k, v in (err.get("ctx") or {}).items()}
    try:
        msgid.format(**ctx)
    except (KeyError, IndexError, ValueError):
        return english
    return Msg.worded(english, msgid, **ctx)
