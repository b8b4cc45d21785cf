"""One webhook request: resolved, checked, pinned, bounded in time and in what is read.

:func:`post` sends a body to a webhook URL the way the delivery loop needs:

* the host is resolved now and every address checked by the
  :class:`~app.core.url_policy.AddressPolicy` (a host that changed its DNS
  answer to a private address since it was registered is refused);
* the connection goes to the checked address itself (the *pinned* address:
  the name is not resolved a second time by the HTTP client), the peer address
  of the connected socket is checked once more, and TLS verifies the
  certificate against the URL's host name (SNI);
* redirects are never followed (a 3xx is a failed attempt);
* one deadline bounds the whole request — name resolution, connection, TLS,
  sending, the answer's status line and headers — however slowly the receiver
  trickles bytes: a watchdog shuts the socket down when it passes;
* at most ``max_answer_bytes`` of the answer's body are read (and discarded),
  then the connection is closed.

The result is an :class:`Attempt` with a *coarse* outcome: ``delivered``,
``http_error`` (the receiver answered, with a non-2xx status), ``no_answer``
(anything else: no connection, reset, timeout, TLS failure, not HTTP — one
outcome, so the delivery log cannot tell a closed port from an open one) or
``refused`` (the policy refused the address: nothing was sent). What the
receiver answered is never kept; the detail of a failure goes to the worker's
log only.
"""

from __future__ import annotations

import http.client
import logging
import socket
import ssl
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass
from urllib.parse import urlsplit

from app.core.url_policy import AddressPolicy, RefusedAddress, Resolver, check_url, resolve

__all__ = ["Attempt", "Outcome", "post"]

log = logging.getLogger(__name__)

#: resolver threads (getaddrinfo cannot be interrupted: it is waited for up to the deadline)
_RESOLVERS = ThreadPoolExecutor(max_workers=4, thread_name_prefix="webhook-dns")


class Outcome:
    """Values of :attr:`Attempt.outcome` (and of the delivery log's coarse error)."""

    DELIVERED = "delivered"
    HTTP_ERROR = "http_error"
    NO_ANSWER = "no_answer"
    REFUSED = "refused"
    ALL = (DELIVERED, HTTP_ERROR, NO_ANSWER, REFUSED)


@dataclass(frozen=True)
class Attempt:
    """What became of one request.

    Attributes
    ----------
    outcome : str
        One of :class:`Outcome`.
    status_code : int or None
        The receiver's HTTP status (``delivered`` and ``http_error`` only).
    seconds : float
        Wall time of the attempt, s.
    detail : str
        Why it failed, for the worker's log (never shown by the API).
    """

    outcome: str
    status_code: int | None
    seconds: float
    detail: str = ""

    @property
    def ok(self) -> bool:
        """The receiver answered 2xx."""
        return self.outcome == Outcome.DELIVERED

    @property
    def summary(self) -> str | None:
        """The coarse text kept in the delivery log (None when delivered)."""
        if self.outcome == Outcome.DELIVERED:
            return None
        if self.outcome == Outcome.HTTP_ERROR:
            return f"HTTP {self.status_code}"
        if self.outcome == Outcome.REFUSED:
            return "refused: the address is not allowed (SSRF policy)"
        return "no answer (no connection, timed out, or not an HTTP answer)"


class _Deadline:
    """Shuts a socket down when the deadline passes (unblocks a recv/send in any state)."""

    def __init__(self, end: float) -> None:
        self.end = end
        self.fired = False
        self._sock: socket.socket | None = None
        self._lock = threading.Lock()
        self._timer = threading.Timer(max(end - time.monotonic(), 0.0), self._fire)
        self._timer.daemon = True
        self._timer.start()

    def left(self) -> float:
        return self.end - time.monotonic()

    def watch(self, sock: socket.socket) -> None:
        with self._lock:
            self._sock = sock
            fired = self.fired
        if fired:
            self._shutdown(sock)

    def _fire(self) -> None:
        with self._lock:
            self.fired = True
            sock = self._sock
        if sock is not None:
            self._shutdown(sock)

    @staticmethod
    def _shutdown(sock: socket.socket) -> None:
        try:
            sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass

    def cancel(self) -> None:
        self._timer.cancel()


class _PinnedConnection(http.client.HTTPConnection):
    """An HTTP connection over a socket connected beforehand (no name resolution of its own)."""

    def __init__(self, host: str, port: int, sock: socket.socket) -> None:
        super().__init__(host, port)
        self.sock = sock

    def connect(self) -> None:  # pragma: no cover - the socket is given; never reconnect
        raise http.client.HTTPException("the pinned connection was closed")


def _connect(ip, port: int, policy: AddressPolicy, deadline: _Deadline) -> socket.socket:
    family = socket.AF_INET6 if ip.version == 6 else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    deadline.watch(sock)
    try:
        sock.settimeout(max(deadline.left(), 0.001))
        sock.connect((str(ip), port))
        peer = sock.getpeername()[0]
        policy.check(peer)  # the address actually connected to
        if str(ip) != peer.split("%", 1)[0]:
            raise RefusedAddress(f"connected to {peer}, not the checked address {ip}")
        return sock
    except BaseException:
        sock.close()
        raise


def _drain(answer: http.client.HTTPResponse, sock: socket.socket, limit: int, deadline: _Deadline) -> int:
    """Read and discard at most ``limit`` bytes of the answer's body before the deadline; bytes read.

    The status is known already: a body that is huge, trickles or breaks off
    changes nothing but how soon the connection is closed.
    """
    read = 0
    try:
        while read < limit and deadline.left() > 0:
            sock.settimeout(max(deadline.left(), 0.001))
            got = answer.read(min(limit - read, 65536))
            if not got:
                break
            read += len(got)
    except (OSError, http.client.HTTPException, ValueError):
        pass
    return read


def post(url: str, body: bytes, headers: dict[str, str], *, policy: AddressPolicy, timeout_s: float,
         max_answer_bytes: int, resolver: Resolver | None = None) -> Attempt:
    """POST ``body`` to ``url`` under the policy; never raises for the receiver's behaviour.

    Parameters
    ----------
    url : str
        The webhook's URL (checked again by :func:`~app.core.url_policy.check_url`).
    body : bytes
    headers : dict
        Request headers (``Host`` and ``Content-Length`` are set here).
    policy : AddressPolicy
    timeout_s : float
        Total time of the attempt, s (> 0).
    max_answer_bytes : int
        Most bytes of the answer's body read (>= 0).
    resolver : callable, optional
        ``resolver(host, port)`` → addresses (tests; default: the system resolver).
    """
    if timeout_s <= 0:
        raise ValueError(f"timeout_s must be > 0 s, got {timeout_s}")
    if max_answer_bytes < 0:
        raise ValueError(f"max_answer_bytes must be >= 0, got {max_answer_bytes}")
    t0 = time.monotonic()
    deadline = _Deadline(t0 + timeout_s)

    def done(outcome: str, code: int | None = None, detail: str = "") -> Attempt:
        return Attempt(outcome, code, round(time.monotonic() - t0, 3), detail)

    sock: socket.socket | None = None
    try:
        try:
            parts = urlsplit(check_url(url))
            future = _RESOLVERS.submit(resolve, url, policy, resolver)
            addresses = future.result(timeout=max(deadline.left(), 0.001))
        except FutureTimeout:
            return done(Outcome.NO_ANSWER, detail="name resolution timed out")
        except RefusedAddress as exc:
            return done(Outcome.REFUSED, detail=str(exc))
        except ValueError as exc:
            return done(Outcome.REFUSED, detail=f"invalid URL: {exc}")
        host = parts.hostname or ""
        https = parts.scheme.lower() == "https"
        port = parts.port or (443 if https else 80)
        errors = []
        for ip in addresses:
            if deadline.left() <= 0:
                break
            try:
                sock = _connect(ip, port, policy, deadline)
                break
            except RefusedAddress as exc:
                return done(Outcome.REFUSED, detail=str(exc))
            except OSError as exc:
                errors.append(f"{ip}: {type(exc).__name__}: {exc}")
        if sock is None:
            return done(Outcome.NO_ANSWER, detail="; ".join(errors) or "timed out")
        if https:
            context = ssl.create_default_context()
            sock.settimeout(max(deadline.left(), 0.001))
            sock = context.wrap_socket(sock, server_hostname=host, do_handshake_on_connect=False)
            deadline.watch(sock)
            sock.do_handshake()
        sock.settimeout(max(deadline.left(), 0.001))
        conn = _PinnedConnection(host, port, sock)
        path = parts.path or "/"
        if parts.query:
            path += "?" + parts.query
        conn.putrequest("POST", path, skip_accept_encoding=True)
        for name, value in {**headers, "Content-Length": str(len(body)), "Connection": "close"}.items():
            conn.putheader(name, value)
        conn.endheaders(body)
        answer = conn.getresponse()  # status line and headers (http.client bounds their size)
        if deadline.fired:  # the head was cut off by the deadline: not an answer
            return done(Outcome.NO_ANSWER, detail="timed out before the answer's head was complete")
        code = answer.status
        _drain(answer, sock, max_answer_bytes, deadline)
        if 200 <= code < 300:
            return done(Outcome.DELIVERED, code)
        return done(Outcome.HTTP_ERROR, code, f"HTTP {code}")
    except (OSError, http.client.HTTPException, ValueError) as exc:
        why = "timed out" if deadline.fired else f"{type(exc).__name__}: {exc}"
        return done(Outcome.NO_ANSWER, detail=why)
    finally:
        deadline.cancel()
        if sock is not None:
            try:
                sock.close()
            except OSError:
                pass
