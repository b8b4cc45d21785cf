"""Tokens of the provider checked: signature through its keys, issuer, audience, expiry, nonce.

Only asymmetric signatures are accepted (RS*, PS*, ES*; never ``none`` nor a shared-secret
HS*), with a key of the provider's key set chosen by the token's ``kid``. An ID token is checked
with Authlib's rules for the code flow (:class:`authlib.oidc.core.CodeIDToken`: ``iss``,
``aud`` holding the client id, ``azp`` when there are several audiences, ``exp``/``iat`` with
``TRACKVKF_OIDC_LEEWAY_S``, the ``nonce`` of the sign-in, ``at_hash``); an access token for the
API with joserfc's claims registry (``iss``, ``aud`` holding ``TRACKVKF_OIDC_API_AUDIENCE``,
``exp``, ``sub``), and a token with a ``nonce`` (an ID token) is no access token.
"""

from __future__ import annotations

from typing import Any

from authlib.oidc.core import CodeIDToken
from joserfc import jwt
from joserfc.errors import (
    BadSignatureError,
    ExpiredTokenError,
    InvalidClaimError,
    InvalidKeyIdError,
    JoseError,
    MissingClaimError,
)
from joserfc.jws import JWSRegistry

from app.oidc.provider import Provider

__all__ = ["TokenRejected", "ALGORITHMS", "check_id_token", "check_access_token", "looks_like_jwt"]

#: signature algorithms accepted (asymmetric only)
ALGORITHMS: tuple[str, ...] = ("RS256", "RS384", "RS512", "PS256", "PS384", "PS512", "ES256", "ES384", "ES512")
_MAX_TOKEN_CHARS = 16 * 1024


class TokenRejected(ValueError):
    """A token failed a check; ``reason`` is one short word or phrase (audit, pages, 401s)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def looks_like_jwt(token: str) -> bool:
    """Whether ``token`` has the shape of a signed JWT (three base64url parts)."""
    parts = token.split(".")
    return len(parts) == 3 and all(parts) and token.startswith("eyJ")


def _reason(exc: Exception) -> str:
    if isinstance(exc, ExpiredTokenError):
        return "expired"
    if isinstance(exc, BadSignatureError):
        return "bad signature"
    if isinstance(exc, InvalidKeyIdError):
        return "signed with a key the provider does not publish"
    if isinstance(exc, (InvalidClaimError, MissingClaimError)):
        claim = getattr(exc, "claim", None) or str(exc)
        return f"{'missing' if isinstance(exc, MissingClaimError) else 'wrong'} claim {claim}"
    return f"malformed ({type(exc).__name__})"


def _decode(token: str, provider: Provider) -> Any:
    """The token with its signature verified by the provider's keys (fetched again once for an
    unknown key id)."""
    if not isinstance(token, str) or not token or len(token) > _MAX_TOKEN_CHARS:
        raise TokenRejected("malformed (empty or too long)")
    meta = provider.metadata()
    algs = [a for a in (meta.signing_algorithms or ALGORITHMS) if a in ALGORITHMS] or list(ALGORITHMS)
    registry = JWSRegistry(algorithms=algs, strict_check_header=False)
    for refresh in (False, True):
        keys = provider.keys(refresh=refresh)
        try:
            return jwt.decode(token, keys, registry=registry)
        except InvalidKeyIdError as exc:
            if refresh:
                raise TokenRejected(_reason(exc)) from None
        except (JoseError, ValueError, TypeError, KeyError) as exc:
            raise TokenRejected(_reason(exc)) from None
    raise AssertionError("unreachable")


def check_id_token(token: str, provider: Provider, *, nonce: str, access_token: str | None = None,
                   now: int | None = None) -> dict[str, Any]:
    """The claims of an ID token the provider issued to trackvkf for this sign-in.

    Parameters
    ----------
    token : str
        The ``id_token`` of the token answer.
    provider : Provider
    nonce : str
        The nonce of the sign-in (its cookie).
    access_token : str, optional
        The access token of the same answer (its ``at_hash`` is checked when present).
    now : int, optional
        Unix time (default: the clock).

    Raises
    ------
    TokenRejected
    ProviderUnavailable
        The keys could not be fetched.
    """
    config = provider.config
    decoded = _decode(token, provider)
    options = {"iss": {"essential": True, "value": config.issuer},
               "aud": {"essential": True, "value": config.client_id},
               "sub": {"essential": True}}
    params = {"nonce": nonce, "client_id": config.client_id}
    if access_token:
        params["access_token"] = access_token
    claims = CodeIDToken(decoded.claims, decoded.header, options, params)
    try:
        claims.validate(now=now, leeway=int(config.leeway_s))
    except (JoseError, ValueError, TypeError) as exc:
        raise TokenRejected(_reason(exc)) from None
    if "nonce" not in claims:
        raise TokenRejected("missing claim nonce")
    return dict(claims)


def check_access_token(token: str, provider: Provider, *, now: int | None = None) -> dict[str, Any]:
    """The claims of a JWT access token the provider issued for trackvkf's API
    (``aud`` holds ``api_audience``).

    Raises
    ------
    TokenRejected
        Also when the configuration accepts no access tokens (no ``api_audience``).
    ProviderUnavailable
    """
    config = provider.config
    if not config.api_audience:
        raise TokenRejected("provider tokens are not accepted (TRACKVKF_OIDC_API_AUDIENCE unset)")
    decoded = _decode(token, provider)
    registry = jwt.JWTClaimsRegistry(
        now=now, leeway=int(config.leeway_s),
        iss={"essential": True, "value": config.issuer},
        aud={"essential": True, "value": config.api_audience},
        exp={"essential": True}, sub={"essential": True},
    )
    try:
        registry.validate(decoded.claims)
    except (JoseError, ValueError, TypeError) as exc:
        raise TokenRejected(_reason(exc)) from None
    if "nonce" in decoded.claims:
        raise TokenRejected("an ID token is no access token")
    return dict(decoded.claims)
