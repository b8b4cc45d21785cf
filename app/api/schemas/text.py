"""The one text type of request bodies: a string without NUL characters.

PostgreSQL's ``text`` cannot hold NUL (``\\u0000``), SQLite stores it: a body field typed
:data:`Text` is refused before any service runs (422 naming the field, the same on both backends), as
a query value with NUL is (:func:`app.api.errors._data_error_handler`). Every free-text field of a
request body uses it; constraints (length, pattern) go beside it in ``Field``.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator

__all__ = ["NUL_MESSAGE", "Text", "without_nul"]

NUL_MESSAGE = "must not contain NUL characters (\\u0000)"


def without_nul(value: str) -> str:
    """``value`` unchanged; :class:`ValueError` if it holds a NUL character."""
    if "\x00" in value:
        raise ValueError(NUL_MESSAGE)
    return value


#: A request body's text: NUL refused (422 naming the field).
Text = Annotated[str, AfterValidator(without_nul)]
