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

from app.oidc.config import OidcConfig
from app.oidc.provider import ProviderUnavailable
from app.oidc.tokens import TokenRejected

__all__ = ["OidcConfig", "ProviderUnavailable", "TokenRejected"]
