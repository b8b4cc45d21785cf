"""Corporate sign-in: OpenID Connect (authorization code + PKCE) beside local users and API keys.

``config``    the provider, the client, the claims and the mapping of groups to roles, from the
              settings (``TRACKVKF_OIDC_*``)
``provider``  the provider's discovery document and signing keys, fetched and kept per process;
              :class:`ProviderUnavailable` when it cannot be reached
``tokens``    ID tokens and access tokens checked: signature through the provider's keys,
              issuer, audience, expiry, nonce (Authlib's ID token rules on joserfc)
``flow``      the browser's sign-in: the authorization request (state, nonce and PKCE verifier
              in a signed cookie), the code exchange of the callback, the provider's sign-out URL
``accounts``  the local account of a signed-in identity (created or updated at each sign-in,
              its role from its groups), its session and audit entry; a bearer token → principal

docs/security.md ("Corporate sign-in") says how to register trackvkf at a provider.
"""

from __future__ import annotations

from typing import Any

from app.oidc.config import OidcConfig

__all__ = ["OidcConfig", "ProviderUnavailable", "TokenRejected"]


def __getattr__(name: str) -> Any:
    """``ProviderUnavailable`` and ``TokenRejected``, imported when first named: their modules load
    httpx, Authlib and joserfc, which the processes that sign nobody in (the worker, the command
    line, the health check) need not import with the settings (``app.oidc.settings`` imports
    :mod:`app.oidc.config`)."""
    if name == "ProviderUnavailable":
        from app.oidc.provider import ProviderUnavailable

        return ProviderUnavailable
    if name == "TokenRejected":
        from app.oidc.tokens import TokenRejected

        return TokenRejected
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
