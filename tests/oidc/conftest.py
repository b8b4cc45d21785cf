"""Fixtures of the corporate sign-in tests: a real OpenID provider on 127.0.0.1 (Authlib's server
components, :mod:`tests.oidc.provider`) and the real service (uvicorn, ``tests/e2e/conftest.py``)
configured to sign in there.

The provider's accounts and their groups, mapped to trackvkf's roles by the service's settings:

=========  ====================================  ==========================
user       groups at the provider                role in trackvkf
=========  ====================================  ==========================
alice      track-engineers                       engineer
bob        track-admins, staff                   admin (the highest)
dave       track-viewers                         viewer
carol      staff                                 none: refused
erin       track-engineers                       refused: a local user is erin
=========  ====================================  ==========================
"""

from __future__ import annotations

import json
import secrets
import urllib.parse as up
from collections.abc import Iterator
from dataclasses import dataclass

import httpx
import pytest
from authlib.oauth2.rfc7636 import create_s256_code_challenge

from tests.e2e.conftest import Service, running_service
from tests.oidc.provider import OpenIDProvider, ProviderUser

CLIENT_ID, CLIENT_SECRET = "trackvkf", "trackvkf-client-secret"
#: another application of the organisation that calls trackvkf's API with its users' tokens
SCRIPT_ID, SCRIPT_SECRET, SCRIPT_REDIRECT = "ops-script", "ops-script-secret", "http://127.0.0.1:9/cb"
API_AUDIENCE = "api://trackvkf"
PROVIDER_NAME = "Test provider"
ROLE_GROUPS = {"track-admins": "admin", "track-engineers": "engineer", "track-viewers": "viewer"}
USERS = [
    ProviderUser("0a1f-alice", "alice", "alice password", ["track-engineers"]),
    ProviderUser("0b2e-bob", "bob", "bob password", ["track-admins", "staff"]),
    ProviderUser("0d4c-dave", "dave", "dave password", ["track-viewers"]),
    ProviderUser("0c3d-carol", "carol", "carol password", ["staff"]),
    ProviderUser("0e5b-erin", "erin", "erin password", ["track-engineers"]),
]
PASSWORDS = {u.username: u.password for u in USERS}


def oidc_env(issuer: str) -> dict[str, str]:
    """The service's settings for a provider at ``issuer``."""
    return {
        "TRACKVKF_OIDC_ISSUER": issuer, "TRACKVKF_OIDC_CLIENT_ID": CLIENT_ID,
        "TRACKVKF_OIDC_CLIENT_SECRET": CLIENT_SECRET, "TRACKVKF_OIDC_PROVIDER_NAME": PROVIDER_NAME,
        "TRACKVKF_OIDC_ROLE_GROUPS": json.dumps(ROLE_GROUPS), "TRACKVKF_OIDC_API_AUDIENCE": API_AUDIENCE,
        "TRACKVKF_OIDC_TIMEOUT_S": "5",
    }


@dataclass
class SignInSetup:
    """The provider and the service that trusts it."""

    provider: OpenIDProvider
    service: Service

    @property
    def base_url(self) -> str:
        return self.service.base_url


@pytest.fixture(scope="module")
def oidc(tmp_path_factory) -> Iterator[SignInSetup]:
    """The provider, and the real service configured for it (API only: no runs needed)."""
    with OpenIDProvider(PROVIDER_NAME, USERS) as provider:
        with running_service(tmp_path_factory.mktemp("oidc-service"),
                             env_overrides=oidc_env(provider.issuer)) as svc:
            provider.register_client(CLIENT_ID, CLIENT_SECRET, [f"{svc.base_url}/login/oidc/callback"],
                                     [f"{svc.base_url}/login"])
            provider.register_client(SCRIPT_ID, SCRIPT_SECRET, [SCRIPT_REDIRECT])
            yield SignInSetup(provider, svc)


@pytest.fixture
def fresh_lifetimes(oidc) -> Iterator[OpenIDProvider]:
    """The provider, its token lifetimes and API audience restored after the test."""
    p = oidc.provider
    saved = (p.id_token_lifetime_s, p.access_token_lifetime_s, p.api_audience)
    p.api_audience = API_AUDIENCE
    try:
        yield p
    finally:
        p.id_token_lifetime_s, p.access_token_lifetime_s, p.api_audience = saved


def provider_tokens(provider: OpenIDProvider, username: str, *, client_id: str = SCRIPT_ID,
                    client_secret: str = SCRIPT_SECRET, redirect_uri: str = SCRIPT_REDIRECT) -> dict:
    """The token answer of the provider to an application (``client_id``) its user ``username``
    signed in to: the authorization code flow with PKCE over HTTP, as a script with a browser
    window would do it."""
    verifier = secrets.token_urlsafe(48)
    query = {"response_type": "code", "client_id": client_id, "redirect_uri": redirect_uri,
             "scope": "openid profile email", "state": secrets.token_urlsafe(8),
             "nonce": secrets.token_urlsafe(8), "code_challenge": create_s256_code_challenge(verifier),
             "code_challenge_method": "S256"}
    url = f"{provider.issuer}/authorize?{up.urlencode(query)}"
    with httpx.Client(timeout=10) as client:
        r = client.post(url, data={"username": username, "password": PASSWORDS[username]})
        assert r.status_code == 302, r.text
        code = up.parse_qs(up.urlsplit(r.headers["location"]).query)["code"][0]
        r = client.post(f"{provider.issuer}/token", auth=(client_id, client_secret),
                        data={"grant_type": "authorization_code", "code": code, "redirect_uri": redirect_uri,
                              "code_verifier": verifier})
        assert r.status_code == 200, r.text
        return r.json()
