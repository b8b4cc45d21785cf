"""Security headers on every answer: pages, API answers, static files, errors.

One pure ASGI middleware (:class:`SecurityHeadersMiddleware`) adds

* ``Content-Security-Policy`` (:data:`CONTENT_SECURITY_POLICY`): everything from
  the server itself, scripts only from files (no inline script, no ``eval``),
  no plugins, no framing, forms only to the server;
* ``X-Frame-Options: DENY`` (older browsers; ``frame-ancestors 'none'`` in the CSP),
* ``X-Content-Type-Options: nosniff``,
* ``Referrer-Policy: same-origin``

to each response that does not set the header itself: a route with an inline
script of its own (the Swagger UI page) sends the policy with that script's
hash (:func:`content_security_policy`, :func:`inline_script_hashes`).
"""

from __future__ import annotations

import base64
import hashlib
import re
from collections.abc import Iterable

from starlette.types import ASGIApp, Message, Receive, Scope, Send

__all__ = [
    "CONTENT_SECURITY_POLICY",
    "SECURITY_HEADERS",
    "SecurityHeadersMiddleware",
    "content_security_policy",
    "inline_script_hashes",
]

_DIRECTIVES: tuple[tuple[str, str], ...] = (
    ("default-src", "'self'"),
    ("script-src", "'self'"),
    # Plotly.js and the pages set style attributes from JS: inline styles are allowed, scripts not
    ("style-src", "'self' 'unsafe-inline'"),
    # data:/blob: images: Plotly's PNG download and Swagger UI's icons
    ("img-src", "'self' data: blob:"),
    ("font-src", "'self' data:"),
    ("connect-src", "'self'"),
    ("object-src", "'none'"),
    ("base-uri", "'none'"),
    ("form-action", "'self'"),
    ("frame-ancestors", "'none'"),
)


def content_security_policy(script_hashes: Iterable[str] = ()) -> str:
    """The service's Content-Security-Policy, optionally allowing inline scripts by hash.

    Parameters
    ----------
    script_hashes : iterable of str
        CSP source expressions such as ``'sha256-...'`` (see
        :func:`inline_script_hashes`) added to ``script-src``.
    """
    extra = " ".join(script_hashes)
    parts = []
    for name, value in _DIRECTIVES:
        if name == "script-src" and extra:
            value = f"{value} {extra}"
        parts.append(f"{name} {value}")
    return "; ".join(parts)


#: the policy of every answer that sets none itself
CONTENT_SECURITY_POLICY = content_security_policy()

#: header name (lower case) → value, added to every answer that lacks the header
SECURITY_HEADERS: dict[str, str] = {
    "content-security-policy": CONTENT_SECURITY_POLICY,
    "x-frame-options": "DENY",
    "x-content-type-options": "nosniff",
    "referrer-policy": "same-origin",
}

_INLINE_SCRIPT = re.compile(r"<script(?![^>]*\bsrc=)[^>]*>(.*?)</script>", re.IGNORECASE | re.DOTALL)


def inline_script_hashes(html: str) -> list[str]:
    """CSP hash sources (``'sha256-<base64>'``) of the inline ``<script>`` blocks of ``html``."""
    return [
        "'sha256-" + base64.b64encode(hashlib.sha256(body.encode("utf-8")).digest()).decode() + "'"
        for body in _INLINE_SCRIPT.findall(html)
    ]


_ENCODED = [(name.encode("latin-1"), value.encode("latin-1")) for name, value in SECURITY_HEADERS.items()]


class SecurityHeadersMiddleware:
    """ASGI middleware adding :data:`SECURITY_HEADERS` to every HTTP response.

    A header the response already carries is left as it is (a route may send
    its own CSP). Pure ASGI: streamed answers pass through untouched.
    """

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {name.lower() for name, _ in headers}
                headers.extend((name, value) for name, value in _ENCODED if name not in present)
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)
