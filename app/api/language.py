"""The language a request is answered in: the user's choice kept with the account, else the
browser's ``Accept-Language``, else English (:func:`app.core.i18n.negotiate`).

The principal is the one the access check found for the request (a route's dependencies run
before its answer and any error it raises); a request answered before anyone was recognised
(the login page, a 401) follows the browser.
"""

from __future__ import annotations

from starlette.requests import HTTPConnection

from app.core.i18n import Language, negotiate

__all__ = ["request_language"]


def request_language(request: HTTPConnection) -> Language:
    """The :class:`~app.core.i18n.Language` of ``request``."""
    principal = getattr(request.state, "principal", None)
    chosen = getattr(principal, "language", None)
    return negotiate(request.headers.get("accept-language"), chosen)
