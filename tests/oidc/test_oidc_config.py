"""The OpenID Connect settings and the pieces of the sign-in that need no provider: groups →
role, the user name of a token, the signed cookie of a sign-in in progress."""

from __future__ import annotations

import time

import pytest
from pydantic import ValidationError

from app.core.config import ProductionConfigError
from app.oidc.config import OidcConfig
from app.oidc.flow import PendingSignIn, seal, unseal
from app.oidc.tokens import looks_like_jwt
from app.settings import Settings

CONFIG = OidcConfig(issuer="https://id.example/realms/rail", client_id="trackvkf",
                    role_groups={"track-admins": "admin", "track-engineers": "engineer", "staff": "viewer"},
                    groups_claim="realm_access.roles")


def test_the_highest_role_of_the_mapped_groups():
    assert CONFIG.role_of(["staff", "track-engineers", "canteen"]) == "engineer"
    assert CONFIG.role_of(["track-admins", "staff"]) == "admin"
    assert CONFIG.role_of(["canteen"]) is None
    assert OidcConfig(issuer="https://i", client_id="c", default_role="viewer").role_of(["canteen"]) == "viewer"


def test_groups_from_a_dotted_claim_path():
    claims = {"realm_access": {"roles": ["staff", 7, "track-admins"]}, "groups": ["ignored"]}
    assert CONFIG.groups_of(claims) == ["staff", "track-admins"]
    assert CONFIG.groups_of({"realm_access": "staff"}) == []
    assert OidcConfig(issuer="https://i", client_id="c").groups_of({"groups": "one"}) == ["one"]


def test_the_user_name_is_the_first_usable_claim():
    assert CONFIG.username_of({"preferred_username": "j.doe@rail.example", "sub": "x"}) == "j.doe@rail.example"
    assert CONFIG.username_of({"preferred_username": "Jörg Müller", "email": "jm@rail.example"}) == "jm@rail.example"
    assert CONFIG.username_of({"preferred_username": "x" * 65, "sub": "0f1e-2d3c"}) == "0f1e-2d3c"
    assert CONFIG.username_of({"name": "no usable claim", "sub": "a b"}) is None


def test_a_bad_mapping_is_refused_naming_it():
    with pytest.raises(ValueError, match="role_groups"):
        OidcConfig(issuer="https://i", client_id="c", role_groups={"g": "superuser"})
    with pytest.raises(ValidationError, match="oidc_role_groups"):
        Settings(oidc_issuer="https://i", oidc_client_id="c", oidc_client_secret="s",
                 oidc_role_groups={"g": "root"})
    with pytest.raises(ValidationError, match="oidc_client_secret"):
        Settings(oidc_issuer="https://i", oidc_client_id="c")
    with pytest.raises(ValidationError, match="oidc_scopes"):
        Settings(oidc_scopes="profile email")
    with pytest.raises(ValidationError, match="oidc_api_audience"):
        Settings(oidc_api_audience="api://trackvkf")
    public = Settings(oidc_issuer="https://i", oidc_client_id="c", oidc_token_auth_method="none")
    assert OidcConfig.from_settings(public).client_secret is None
    assert OidcConfig.from_settings(Settings()) is None


def test_production_needs_an_https_issuer():
    settings = Settings(env="production", secret_key="k" * 40, oidc_issuer="http://id.example",
                        oidc_client_id="c", oidc_client_secret="s")
    with pytest.raises(ProductionConfigError, match="TRACKVKF_OIDC_ISSUER"):
        settings.check_production()


def test_the_pending_sign_in_cookie_is_signed_and_expires():
    pending = PendingSignIn("state", "nonce", "verifier", "/condition", time.time() + 60)
    value = seal(pending, "secret")
    assert unseal(value, "secret") == pending
    assert unseal(value, "another secret") is None
    payload, mac = value.rsplit(".", 1)
    assert unseal(f"{payload}x.{mac}", "secret") is None
    assert unseal(value, "secret", now=time.time() + 120) is None
    assert unseal(None, "secret") is None and unseal("garbage", "secret") is None


def test_jwt_shaped_tokens_and_api_keys_are_told_apart():
    assert looks_like_jwt("eyJhbGciOiJSUzI1NiJ9.eyJzdWIiOiJ4In0.c2ln")
    assert not looks_like_jwt("tvk_0123abcd_" + "x" * 43)
    assert not looks_like_jwt("eyJ..")
