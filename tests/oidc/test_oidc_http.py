"""Corporate sign-in over HTTP against a real OpenID provider (tests/oidc/provider.py) and the real
service: the code flow with PKCE, the role from the groups, refusals audited, sign-out at the
provider, and the provider's access tokens on the REST API (accepted when valid; expired,
foreign, other-audience, ID and tampered tokens refused)."""

from __future__ import annotations

import urllib.parse as up
from contextlib import closing

import httpx
import pytest

from app.db import auth_crud
from app.db.session import Database
from tests.api.support import TEST_PASSWORD_COST
from tests.oidc.conftest import (
    API_AUDIENCE,
    CLIENT_ID,
    PASSWORDS,
    PROVIDER_NAME,
    SCRIPT_ID,
    SCRIPT_REDIRECT,
    SCRIPT_SECRET,
    SignInSetup,
    provider_tokens,
)
from tests.oidc.provider import OpenIDProvider, ProviderUser


def http_sign_in(oidc: SignInSetup, username: str, next_path: str = "/condition") -> tuple[httpx.Client, httpx.Response]:
    """A cookie-keeping client that signed in through the provider as ``username``, and the
    callback's answer (the client is the caller's to close)."""
    client = httpx.Client(base_url=oidc.base_url, timeout=15)
    r = client.get("/login/oidc", params={"next": next_path})
    assert r.status_code == 303, r.text
    authorize = r.headers["location"]
    assert authorize.startswith(f"{oidc.provider.issuer}/authorize?")
    r = httpx.post(authorize, data={"username": username, "password": PASSWORDS[username]}, timeout=15)
    assert r.status_code == 302, r.text
    callback = r.headers["location"]
    assert callback.startswith(f"{oidc.base_url}/login/oidc/callback?")
    return client, client.get(callback)


def _audit(oidc: SignInSetup, target: str) -> list[dict]:
    with oidc.service.client(timeout=15) as admin:
        r = admin.get("/api/v1/audit", params={"action": "auth.login", "limit": 100})
        assert r.status_code == 200, r.text
        return [e for e in r.json()["items"] if e["target"] == target]


def test_the_authorization_request_uses_pkce_state_and_nonce(oidc):
    with httpx.Client(base_url=oidc.base_url, timeout=15) as client:
        r = client.get("/login/oidc", params={"next": "/map"})
    assert r.status_code == 303
    query = up.parse_qs(up.urlsplit(r.headers["location"]).query)
    assert query["response_type"] == ["code"] and query["client_id"] == [CLIENT_ID]
    assert query["code_challenge_method"] == ["S256"] and len(query["code_challenge"][0]) == 43
    assert len(query["state"][0]) >= 24 and len(query["nonce"][0]) >= 24
    assert "openid" in query["scope"][0].split()
    assert query["redirect_uri"] == [f"{oidc.base_url}/login/oidc/callback"]
    cookie = r.headers["set-cookie"]
    assert "trackvkf_oidc=" in cookie and "HttpOnly" in cookie and "Path=/login/oidc/callback" in cookie
    assert "SameSite=lax" in cookie or "SameSite=Lax" in cookie


def test_sign_in_creates_the_account_with_the_role_of_its_groups(oidc):
    client, r = http_sign_in(oidc, "alice", "/condition?line=SIM")
    with closing(client):
        assert r.status_code == 200, r.text
        assert 'http-equiv="refresh"' in r.text and "/condition?line=SIM" in r.text
        assert "Signed in as alice (engineer)" in r.text
        me = client.get("/api/v1/auth/me")
        assert me.status_code == 200 and me.json() == {"name": "alice", "role": "engineer", "kind": "user",
                                                   "language": None, "answered_in": "en"}
        assert client.get("/condition").status_code == 200  # a page of the dashboard
    with oidc.service.client(timeout=15) as admin:
        users = {u["username"]: u for u in admin.get("/api/v1/auth/users").json()["items"]}
    assert users["alice"]["auth_source"] == "oidc" and users["alice"]["role"] == "engineer"
    assert users["alice"]["created_by"] == f"oidc:{PROVIDER_NAME}"
    ok = [e for e in _audit(oidc, "alice") if e["outcome"] == "ok"]
    assert ok and ok[0]["detail"]["method"] == "oidc" and ok[0]["detail"]["groups"] == ["track-engineers"]
    assert ok[0]["actor_kind"] == "user"


@pytest.mark.parametrize(("username", "role", "admin_status"), [("bob", "admin", 200), ("dave", "viewer", 403)])
def test_the_highest_role_of_the_groups_is_given(oidc, username, role, admin_status):
    client, r = http_sign_in(oidc, username)
    with closing(client):
        assert r.status_code == 200, r.text
        assert client.get("/api/v1/auth/me").json()["role"] == role
        assert client.get("/api/v1/auth/users").status_code == admin_status


def test_a_user_in_no_mapped_group_is_refused_and_audited(oidc):
    client, r = http_sign_in(oidc, "carol")
    with closing(client):
        assert r.status_code == 403
        assert "No access" in r.text and "carol is in none of the groups" in r.text and "/login" in r.text
        assert "trackvkf_session" not in client.cookies
        assert client.get("/api/v1/auth/me").status_code == 401
    denied = [e for e in _audit(oidc, "carol") if e["outcome"] == "denied"]
    assert denied and "none of the groups" in denied[0]["detail"]["reason"]


def test_a_local_user_name_is_not_taken_over(oidc):
    db = Database(oidc.service.database_url)
    try:
        with db.write() as session:
            auth_crud.create_user(session, "erin", "a local password of erin", "viewer",
                                  password_cost=TEST_PASSWORD_COST)
    finally:
        db.dispose()
    client, r = http_sign_in(oidc, "erin")
    with closing(client):
        assert r.status_code == 403 and "belongs to a local user" in r.text
        assert client.get("/api/v1/auth/me").status_code == 401


def test_an_account_of_the_provider_has_no_local_password(oidc):
    client, r = http_sign_in(oidc, "alice")
    client.close()
    with httpx.Client(base_url=oidc.base_url, timeout=15) as anon:
        r = anon.post("/api/v1/auth/login", json={"username": "alice", "password": "anything at all"})
        assert r.status_code == 401
    with oidc.service.client(timeout=15) as admin:
        r = admin.patch("/api/v1/auth/users/alice", json={"password": "a new local password"})
        assert r.status_code == 422 and r.json()["field"] == "password"


def test_the_callback_checks_state_and_the_browser(oidc):
    with httpx.Client(base_url=oidc.base_url, timeout=15) as client:
        authorize = client.get("/login/oidc").headers["location"]
        callback = httpx.post(authorize, data={"username": "alice", "password": PASSWORDS["alice"]}).headers["location"]
        query = up.parse_qs(up.urlsplit(callback).query)
        forged = client.get("/login/oidc/callback", params={"code": query["code"][0], "state": "another state"})
        assert forged.status_code == 400 and "state does not match" in forged.text
    with httpx.Client(base_url=oidc.base_url, timeout=15) as other_browser:  # no sign-in begun there
        r = other_browser.get(callback)
        assert r.status_code == 400 and "no sign-in in progress in this browser" in r.text
    with httpx.Client(base_url=oidc.base_url, timeout=15) as client:
        r = client.get("/login/oidc/callback", params={"error": "access_denied", "error_description": "the user said no"})
        assert r.status_code == 400 and "the user said no" in r.text


def test_an_expired_id_token_is_refused(oidc, fresh_lifetimes):
    fresh_lifetimes.id_token_lifetime_s = -3600
    client, r = http_sign_in(oidc, "alice")
    with closing(client):
        assert r.status_code == 400 and "Sign-in not verified" in r.text and "expired" in r.text
        assert client.get("/api/v1/auth/me").status_code == 401


def test_sign_out_ends_the_session_here_and_at_the_provider(oidc):
    client, r = http_sign_in(oidc, "alice")
    with closing(client):
        csrf = client.cookies["trackvkf_csrf"]
        r = client.post("/api/v1/auth/logout", headers={"X-CSRF-Token": csrf})
        assert r.status_code == 200, r.text
        url = r.json()["end_session_url"]
        assert url.startswith(f"{oidc.provider.issuer}/logout?")
        query = up.parse_qs(up.urlsplit(url).query)
        assert query["client_id"] == [CLIENT_ID] and query["post_logout_redirect_uri"] == [f"{oidc.base_url}/login"]
        assert client.get("/api/v1/auth/me").status_code == 401
        before = len(oidc.provider.logouts)
        at_provider = httpx.get(url, timeout=15)
        assert at_provider.status_code == 302 and at_provider.headers["location"] == f"{oidc.base_url}/login"
        assert len(oidc.provider.logouts) == before + 1 and oidc.provider.logouts[-1]["preferred_username"] == "alice"


# --- the provider's access tokens on the REST API ------------------------------------------------
def _me(oidc: SignInSetup, token: str) -> httpx.Response:
    return httpx.get(f"{oidc.base_url}/api/v1/auth/me", headers={"Authorization": f"Bearer {token}"}, timeout=15)


def test_an_access_token_of_the_provider_is_accepted_with_the_role_of_its_groups(oidc, fresh_lifetimes):
    alice = provider_tokens(oidc.provider, "alice")["access_token"]
    r = _me(oidc, alice)
    assert r.status_code == 200, r.text
    assert r.json() == {"name": "alice", "role": "engineer", "kind": "oidc_token", "language": None,
                        "answered_in": "en"}
    headers = {"Authorization": f"Bearer {alice}"}
    assert httpx.get(f"{oidc.base_url}/api/v1/runs", headers=headers, timeout=15).status_code == 200
    assert httpx.get(f"{oidc.base_url}/api/v1/auth/users", headers=headers, timeout=15).status_code == 403
    bob = provider_tokens(oidc.provider, "bob")["access_token"]
    assert httpx.get(f"{oidc.base_url}/api/v1/auth/users", headers={"Authorization": f"Bearer {bob}"},
                     timeout=15).status_code == 200


def test_expired_foreign_and_misdirected_tokens_are_refused(oidc, fresh_lifetimes):
    def refused(token: str, why: str) -> None:
        r = _me(oidc, token)
        assert r.status_code == 401, r.text
        assert r.json()["field"] == "authorization" and why in r.json()["detail"], r.json()

    fresh_lifetimes.access_token_lifetime_s = -3600
    refused(provider_tokens(oidc.provider, "alice")["access_token"], "expired")
    fresh_lifetimes.access_token_lifetime_s = 300

    fresh_lifetimes.api_audience = "api://another-application"
    refused(provider_tokens(oidc.provider, "alice")["access_token"], "claim aud")
    fresh_lifetimes.api_audience = API_AUDIENCE

    answer = provider_tokens(oidc.provider, "alice")
    refused(answer["id_token"], "claim aud")  # an ID token (audience: the script) is no API token
    head, payload, signature = answer["access_token"].split(".")
    refused(f"{head}.{payload}.{signature[:-4]}AAAA", "signature")
    refused(provider_tokens(oidc.provider, "carol")["access_token"], "none of the groups")

    # another provider, with its own keys and issuer, and the same user names
    with OpenIDProvider("Foreign provider", [ProviderUser("0a1f-alice", "alice", PASSWORDS["alice"],
                                                          ["track-admins"])]) as foreign:
        foreign.api_audience = API_AUDIENCE
        foreign.register_client(SCRIPT_ID, SCRIPT_SECRET, [SCRIPT_REDIRECT])
        refused(provider_tokens(foreign, "alice")["access_token"], "key the provider does not publish")


def test_a_deactivated_account_is_refused_with_its_token(oidc, fresh_lifetimes):
    client, r = http_sign_in(oidc, "dave")
    client.close()
    token = provider_tokens(oidc.provider, "dave")["access_token"]
    with oidc.service.client(timeout=15) as admin:
        assert admin.patch("/api/v1/auth/users/dave", json={"active": False}).status_code == 200
        try:
            r = _me(oidc, token)
            assert r.status_code == 401 and "deactivated" in r.json()["detail"]
            again, page = http_sign_in(oidc, "dave")
            again.close()
            assert page.status_code == 403 and "deactivated" in page.text
        finally:
            assert admin.patch("/api/v1/auth/users/dave", json={"active": True}).status_code == 200
