"""Per role, every route allows and denies as its declared policy says (table-driven).

The table is derived from the app's routes: each route's policy is what its
dependencies declare (:func:`app.api.deps.route_policy`: ``public``,
``require_role(role)`` or ``require_page_login(role)``). A route without a
declared policy fails the test, so routes added later are covered
automatically. The declared policies are checked against the rules of the
issue (viewer reads; engineer uploads, reprocesses, cancels, imports reference
data; admin manages users, keys, webhooks, deletions and reads the audit log), and each
route is then requested as anonymous, viewer, engineer and admin.
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import pytest

from app.api.deps import iter_routes, route_policy
from app.core.security import ROLES, role_allows
from app.main import create_app
from tests.api.support import make_settings
from tests.security.conftest import PASSWORD

#: Routes that need no authentication at all.
PUBLIC = {
    ("GET", "/api/v1/health"),
    ("POST", "/api/v1/auth/login"),
    ("GET", "/login"),
    ("GET", "/login/oidc"),  # issue 34: corporate sign-in, its start and the provider's callback
    ("GET", "/login/oidc/callback"),
    ("GET", "/favicon.ico"),
    ("GET", "/i18n/{lang}.js"),  # the pages' words: the login page speaks the browser's language too
}
#: State-changing routes any authenticated principal may use (their own session, their language).
SELF_SERVICE = {("POST", "/api/v1/auth/logout"), ("POST", "/api/v1/auth/password"), ("PATCH", "/api/v1/auth/me")}
#: Routes whose required role the issue names explicitly.
EXPLICIT = {
    ("POST", "/api/v1/runs"): "engineer",
    ("POST", "/api/v1/runs/{run_id}/jobs"): "engineer",
    ("POST", "/api/v1/jobs/{job_id}/cancel"): "engineer",
    ("DELETE", "/api/v1/runs/{run_id}"): "admin",
    ("GET", "/api/v1/audit"): "admin",
    ("GET", "/metrics"): "admin",  # issue 24: Prometheus metrics, admin only (an API key for the scraper)
    ("DELETE", "/api/v1/assets/{asset_id}"): "admin",  # issue 25: assets import as engineer, delete as admin
}
_ADMIN_PREFIXES = ("/api/v1/auth/users", "/api/v1/auth/keys", "/api/v1/audit",
                   "/api/v1/webhooks")  # issue 16: an admin configures the alert receivers
_ENGINEER_PREFIXES = ("/api/v1/reference",)
_SAFE = {"GET", "HEAD", "OPTIONS"}


def _routes() -> list[tuple[str, str, tuple[str, str | None] | None, object]]:
    with tempfile.TemporaryDirectory() as tmp:
        app = create_app(make_settings(Path(tmp)))
        app.state.db.dispose()
    out = []
    for route in iter_routes(app):
        methods = getattr(route, "methods", None)
        path = getattr(route, "path", None)
        if not methods or path is None:  # mounts (static files) have no methods
            continue
        for method in sorted(methods - {"HEAD", "OPTIONS"}):
            out.append((method, path, route_policy(route), route))
    return out


ROUTES = _routes()
IDS = [f"{m} {p}" for m, p, _, _ in ROUTES]


def expected_policy(method: str, path: str) -> tuple[str, str | None]:
    """The policy the issue prescribes for a route."""
    if (method, path) in PUBLIC:
        return ("public", None)
    kind = "api" if path.startswith("/api/") or path in ("/openapi.json", "/metrics") else "page"
    if (method, path) in EXPLICIT:
        return (kind, EXPLICIT[(method, path)])
    if path.startswith(_ADMIN_PREFIXES):
        return (kind, "admin")
    if method in _SAFE or (method, path) in SELF_SERVICE:
        return (kind, "viewer")
    if path.startswith(_ENGINEER_PREFIXES):
        return (kind, "engineer")
    return (kind, "engineer")  # any other change needs at least engineer


def test_every_route_declares_a_policy():
    missing = [f"{m} {p}" for m, p, policy, _ in ROUTES if policy is None]
    assert not missing, f"routes without require_role/require_page_login/public: {missing}"


@pytest.mark.parametrize(("method", "path", "policy", "route"), ROUTES, ids=IDS)
def test_declared_policy_matches_the_rules(method, path, policy, route):
    if method not in _SAFE and (method, path) not in SELF_SERVICE | PUBLIC:
        assert policy is not None and policy[1] in ("engineer", "admin"), (
            f"{method} {path} changes state but admits {policy}"
        )
    assert policy == expected_policy(method, path)


def _url(path: str, route) -> str:
    """Fill path parameters with values that name nothing (ids far out of use)."""
    fields = {f.name: f for f in getattr(getattr(route, "dependant", None), "path_params", [])}

    def value(match: re.Match) -> str:
        name = match.group(1).split(":")[0]
        field = fields.get(name)
        annotation = getattr(getattr(field, "field_info", None), "annotation", None)
        if annotation is int or name.endswith("_id"):
            return "2147480000"
        return "nobody"

    return re.sub(r"\{([^}]+)\}", value, path)


def _request(client, method: str, url: str, headers: dict[str, str]):
    kwargs = {"headers": headers}
    if method in ("POST", "PUT", "PATCH"):
        kwargs["json"] = {}
    return client.request(method, url, **kwargs)


@pytest.mark.parametrize(("method", "path", "policy", "route"), ROUTES, ids=IDS)
def test_each_role_is_allowed_or_denied(secured_shared, method, path, policy, route):
    secured = secured_shared
    secured.client.cookies.clear()
    assert policy is not None
    kind, required = policy
    url = _url(path, route)
    for role in (None, *ROLES):
        response = _request(secured.client, method, url, secured.headers(role))
        who = role or "anonymous"
        assert response.status_code < 500, f"{method} {url} as {who}: {response.status_code}"
        if kind == "public":
            assert response.status_code not in (401, 403), f"{method} {url} as {who}"
        elif role is None:
            if kind == "api":
                assert response.status_code == 401, f"{method} {url} anonymous: {response.status_code}"
                assert response.json()["field"] in ("authentication", "authorization")
            else:
                assert response.status_code == 303, f"{method} {url} anonymous: {response.status_code}"
                assert response.headers["location"].startswith("/login?next=")
        elif role_allows(role, required):
            assert response.status_code not in (401, 403), (
                f"{method} {url} as {who} (needs {required}): {response.status_code} {response.text}"
            )
        else:
            assert response.status_code == 403, (
                f"{method} {url} as {who} (needs {required}): {response.status_code}"
            )
            assert response.json()["field"] == "role"


def _login(client, username: str) -> str:
    response = client.post("/api/v1/auth/login", json={"username": username, "password": PASSWORD})
    assert response.status_code == 200, response.text
    return client.cookies["trackvkf_csrf"]


UNSAFE = [(m, p, pol, r) for m, p, pol, r in ROUTES if m not in _SAFE and pol and pol[0] != "public"]


@pytest.mark.parametrize(("method", "path", "policy", "route"), UNSAFE, ids=[f"{m} {p}" for m, p, _, _ in UNSAFE])
def test_cookie_sessions_need_the_csrf_header(secured_shared, method, path, policy, route):
    secured = secured_shared
    secured.client.cookies.clear()
    csrf = _login(secured.client, "alice")
    url = _url(path, route)
    response = _request(secured.client, method, url, {})
    assert response.status_code == 403 and response.json()["field"] == "csrf", response.text
    response = _request(secured.client, method, url, {"X-CSRF-Token": "0" * 64})
    assert response.status_code == 403 and response.json()["field"] == "csrf", response.text
    response = _request(secured.client, method, url, {"X-CSRF-Token": csrf})
    assert response.status_code not in (401, 403), f"{method} {url}: {response.status_code} {response.text}"


def test_session_cookie_roles_follow_the_user(secured_shared):
    secured = secured_shared
    secured.client.cookies.clear()
    _login(secured.client, "vic")
    assert secured.client.get("/api/v1/runs").status_code == 200
    assert secured.client.get("/api/v1/auth/me").json() == {"name": "vic", "role": "viewer", "kind": "user",
                                                          "language": None, "answered_in": "en"}
    csrf = secured.client.cookies["trackvkf_csrf"]
    response = secured.client.delete("/api/v1/runs/1", headers={"X-CSRF-Token": csrf})
    assert response.status_code == 403 and response.json()["field"] == "role"
    assert secured.client.get("/docs").status_code == 200
    secured.client.cookies.clear()
