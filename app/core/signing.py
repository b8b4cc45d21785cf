"""Signatures of webhook bodies: HMAC-SHA256 over the timestamp and the body.

Every webhook request carries the header::

    X-Trackvkf-Signature: t=<unix seconds>,v1=<hex HMAC-SHA256(secret, "<t>.<body>")>

A receiver recomputes the HMAC with the webhook's secret over the timestamp, a
dot and the raw request body (bytes as received), compares it in constant time
and rejects timestamps too far from its clock (replays). :func:`verify` does
exactly that and can be copied into a receiver.

While a webhook's secret is being rotated the header carries one ``v1=`` per
valid secret (the new one first): ``t=<unix>,v1=<new>,v1=<previous>``; a
receiver accepts the request when any of them matches its secret, so it can
switch to the new secret at any time within the grace period.
"""

from __future__ import annotations

import hashlib
import hmac
import time
from collections.abc import Sequence

__all__ = ["SIGNATURE_HEADER", "sign", "signature_header", "verify"]

#: Header carrying the timestamp and the signature.
SIGNATURE_HEADER = "X-Trackvkf-Signature"


def sign(secret: str, timestamp: int, body: bytes) -> str:
    """Hex HMAC-SHA256 of ``"<timestamp>.<body>"`` keyed by ``secret``."""
    return hmac.new(secret.encode(), f"{int(timestamp)}.".encode() + body, hashlib.sha256).hexdigest()


def signature_header(secret: str | Sequence[str], body: bytes, timestamp: int | None = None) -> str:
    """The value of :data:`SIGNATURE_HEADER` for ``body`` (now, unless ``timestamp`` is given);
    one ``v1=`` per secret when several are given (rotation)."""
    t = int(time.time()) if timestamp is None else int(timestamp)
    keys = [secret] if isinstance(secret, str) else list(secret)
    if not keys:
        raise ValueError("secret: at least one secret is needed")
    return ",".join([f"t={t}", *(f"v1={sign(k, t, body)}" for k in keys)])


def verify(secret: str, header: str | None, body: bytes, *, tolerance_s: float = 300.0,
           now: float | None = None) -> bool:
    """Whether ``header`` is a valid signature of ``body`` made within ``tolerance_s`` of ``now``."""
    if not header:
        return False
    pairs = [p.strip().split("=", 1) for p in header.split(",") if "=" in p]
    stamps = [v for k, v in pairs if k == "t"]
    try:
        t = int(stamps[0])
    except (IndexError, ValueError):
        return False
    if abs((time.time() if now is None else now) - t) > tolerance_s:
        return False
    expected = sign(secret, t, body)
    return any(hmac.compare_digest(v, expected) for k, v in pairs if k == "v1")
