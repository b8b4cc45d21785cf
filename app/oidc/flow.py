"""The browser's sign-in at the provider: authorization code flow with PKCE (RFC 7636, S256).

1. :func:`begin` makes a fresh ``state``, ``nonce`` and PKCE ``code_verifier`` and the
   provider's authorization URL; the three values and the page to return to travel in a
   cookie signed with the server secret (HMAC-SHA256, :func:`seal`), valid
   :data:`PENDING_TTL_S` and sent only to the callback path: nothing is kept on the server
   between the two requests, and only the browser that began a sign-in can finish it.
2. :func:`finish`, at the callback: the cookie checked and its ``state`` compared with the
   one the provider sent back, the code exchanged at the token endpoint with the verifier
   (client authentication per ``TRACKVKF_OIDC_TOKEN_AUTH_METHOD``), the ID token checked
   (:func:`app.oidc.tokens.check_id_token`, the cookie's nonce).
3. :func:`end_session_url`: where the browser goes to sign out at the provider too
   (RP-initiated logout), when the provider offers an ``end_session_endpoint``.

The protocol's parameters are Authlib's (``prepare_grant_uri``, ``prepare_token_request``,
``ClientAuth``, ``create_s256_code_challenge``); the HTTP is httpx.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import json
import secrets
import time
from dataclasses import dataclass
from typing import Any

import httpx
from authlib.common.urls import add_params_to_uri
from authlib.oauth2.auth import ClientAuth
from authlib.oauth2.rfc6749.parameters import prepare_grant_uri, prepare_token_request
from authlib.oauth2.rfc7636 import create_s256_code_challenge

from app.oidc.config import OidcConfig
from app.oidc.provider import MAX_DOCUMENT_BYTES, Provider, ProviderUnavailable
from app.oidc.tokens import TokenRejected, check_id_token

__all__ = ["CALLBACK_PATH", "START_PATH", "callback_url", "post_logout_url", "PENDING_COOKIE", "PENDING_TTL_S", "PendingSignIn", "SignedIn", "begin", "finish", "seal",
           "unseal", "end_session_url"]

#: where a browser begins a sign-in, and where the provider sends it back (register this one)
START_PATH = "/login/oidc"
CALLBACK_PATH = "/login/oidc/callback"
#: the cookie of a sign-in in progress (path: the callback)
PENDING_COOKIE = "trackvkf_oidc"
#: how long a sign-in may take at the provider, s
PENDING_TTL_S = 600
_PURPOSE = b"oidc-pending-sign-in:"


@dataclass(frozen=True)
class PendingSignIn:
    """A sign-in begun in this browser: what the callback checks and needs."""

    state: str
    nonce: str
    verifier: str
    next_path: str
    expires: float

    def as_dict(self) -> dict[str, Any]:
        return {"s": self.state, "n": self.nonce, "v": self.verifier, "p": self.next_path, "e": self.expires}


@dataclass(frozen=True)
class SignedIn:
    """The checked outcome of a sign-in: the ID token's claims and the token itself."""

    claims: dict[str, Any]
    id_token: str


def callback_url(config: OidcConfig, base_url: str) -> str:
    """The callback URL: ``TRACKVKF_OIDC_REDIRECT_URI``, else ``base_url`` (this server's) + the path."""
    return config.redirect_uri or base_url.rstrip("/") + CALLBACK_PATH


def post_logout_url(config: OidcConfig, base_url: str) -> str:
    """Where the provider sends the browser after its sign-out: the setting, else the login page."""
    return config.post_logout_redirect_uri or base_url.rstrip("/") + "/login"


def _mac(secret_key: str, payload: bytes) -> str:
    return hmac.new(secret_key.encode("utf-8"), _PURPOSE + payload, hashlib.sha256).hexdigest()


def seal(pending: PendingSignIn, secret_key: str) -> str:
    """The cookie value of ``pending``: ``<base64url JSON>.<HMAC>``."""
    payload = base64.urlsafe_b64encode(json.dumps(pending.as_dict(), separators=(",", ":")).encode()).rstrip(b"=")
    return f"{payload.decode()}.{_mac(secret_key, payload)}"


def unseal(value: str | None, secret_key: str, *, now: float | None = None) -> PendingSignIn | None:
    """The pending sign-in of a cookie value; None when absent, forged, malformed or expired."""
    if not value or len(value) > 4096 or "." not in value:
        return None
    payload, _, mac = value.rpartition(".")
    if not hmac.compare_digest(_mac(secret_key, payload.encode()), mac):
        return None
    try:
        data = json.loads(base64.urlsafe_b64decode(payload + "=" * (-len(payload) % 4)))
        pending = PendingSignIn(str(data["s"]), str(data["n"]), str(data["v"]), str(data["p"]), float(data["e"]))
    except (ValueError, KeyError, TypeError):
        return None
    if pending.expires < (time.time() if now is None else now):
        return None
    return pending


def begin(provider: Provider, *, redirect_uri: str, next_path: str, secret_key: str,
          login_hint: str | None = None) -> tuple[str, str]:
    """Start a sign-in.

    Parameters
    ----------
    provider : Provider
    redirect_uri : str
        The callback URL (registered at the provider).
    next_path : str
        A local path to go to once signed in.
    secret_key : str
        Signs the cookie.
    login_hint : str, optional

    Returns
    -------
    (url, cookie) : tuple of str
        The provider's authorization URL to send the browser to, and the value of
        :data:`PENDING_COOKIE`.

    Raises
    ------
    ProviderUnavailable
    """
    meta = provider.metadata()
    config = provider.config
    pending = PendingSignIn(state=secrets.token_urlsafe(24), nonce=secrets.token_urlsafe(24),
                            verifier=secrets.token_urlsafe(48), next_path=next_path,
                            expires=time.time() + PENDING_TTL_S)
    extra = {"nonce": pending.nonce, "code_challenge": create_s256_code_challenge(pending.verifier),
             "code_challenge_method": "S256"}
    if login_hint:
        extra["login_hint"] = login_hint
    url = prepare_grant_uri(meta.authorization_endpoint, config.client_id, "code", redirect_uri=redirect_uri,
                            scope=config.scopes, state=pending.state, **extra)
    return url, seal(pending, secret_key)


def _token_answer(provider: Provider, code: str, pending: PendingSignIn, redirect_uri: str) -> dict[str, Any]:
    meta = provider.metadata()
    config = provider.config
    body = prepare_token_request("authorization_code", code=code, redirect_uri=redirect_uri,
                                 code_verifier=pending.verifier)
    headers = {"Content-Type": "application/x-www-form-urlencoded", "Accept": "application/json"}
    auth = ClientAuth(config.client_id, config.client_secret or "", config.token_auth_method)
    uri, headers, body = auth.prepare("POST", meta.token_endpoint, headers, body)
    try:
        with provider.client() as client:
            response = client.post(uri, content=body, headers=headers)
    except httpx.HTTPError as exc:
        raise ProviderUnavailable(f"token endpoint {meta.token_endpoint}: {type(exc).__name__}: "
                                  f"{exc or 'no answer'}") from None
    if len(response.content) > MAX_DOCUMENT_BYTES:
        raise ProviderUnavailable(f"token endpoint {meta.token_endpoint}: answer too large")
    try:
        answer = response.json()
    except ValueError:
        answer = None
    if response.status_code >= 500 or not isinstance(answer, dict):
        raise ProviderUnavailable(f"token endpoint {meta.token_endpoint}: HTTP {response.status_code}")
    if response.status_code != 200 or "error" in answer:
        error = str(answer.get("error", f"HTTP {response.status_code}"))[:100]
        raise TokenRejected(f"the provider refused the code ({error})")
    if not isinstance(answer.get("id_token"), str):
        raise TokenRejected("the provider's answer has no ID token (is 'openid' among the scopes?)")
    return answer


def finish(provider: Provider, pending: PendingSignIn | None, *, state: str | None, code: str | None,
           redirect_uri: str) -> SignedIn:
    """Complete a sign-in at the callback.

    Parameters
    ----------
    provider : Provider
    pending : PendingSignIn or None
        The browser's cookie, unsealed (None: none, or expired).
    state, code : str or None
        The callback's query parameters.
    redirect_uri : str
        The same callback URL as in :func:`begin`.

    Raises
    ------
    TokenRejected
        No or an expired sign-in in this browser, another ``state``, the code refused, the ID
        token failing a check.
    ProviderUnavailable
    """
    if pending is None:
        raise TokenRejected("no sign-in in progress in this browser (expired, or begun elsewhere)")
    if not state or not hmac.compare_digest(state.encode(), pending.state.encode()):
        raise TokenRejected("state does not match this browser's sign-in")
    if not code:
        raise TokenRejected("no code in the provider's answer")
    answer = _token_answer(provider, code, pending, redirect_uri)
    claims = check_id_token(answer["id_token"], provider, nonce=pending.nonce,
                            access_token=answer.get("access_token") if isinstance(answer.get("access_token"), str)
                            else None)
    return SignedIn(claims=claims, id_token=answer["id_token"])


def end_session_url(provider: Provider, *, id_token: str | None, post_logout_redirect_uri: str) -> str | None:
    """The provider's sign-out URL for a session begun with ``id_token`` (OpenID Connect
    RP-Initiated Logout 1.0); None when the provider offers none.

    Raises
    ------
    ProviderUnavailable
    """
    meta = provider.metadata()
    if not meta.end_session_endpoint:
        return None
    params = [("client_id", provider.config.client_id), ("post_logout_redirect_uri", post_logout_redirect_uri)]
    if id_token:
        params.insert(0, ("id_token_hint", id_token))
    return add_params_to_uri(meta.end_session_endpoint, params)
