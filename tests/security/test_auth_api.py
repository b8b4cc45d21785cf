"""Login, sessions, API keys, users and the audit log over the API."""

from __future__ import annotations

import datetime as dt

import pytest
from sqlalchemy import text
from sqlalchemy.exc import DatabaseError

from app.core.security import token_digest
from app.db import auth_crud
from app.db.models import ApiKey, AuditEntry
from app.db.session import Database
from tests.api import runfiles
from tests.api.support import auth_headers, make_settings, migrate_database
from tests.security.conftest import PASSWORD


def _login(client, username="alice", password=PASSWORD):
    return client.post("/api/v1/auth/login", json={"username": username, "password": password})


def _stored_hash(keys, username: str) -> str:
    db = Database(keys.settings.database_url)
    try:
        with db.read() as s:
            return auth_crud.get_user(s, username).password_hash
    finally:
        db.dispose()


def _parameters(settings) -> str:
    """The start of an Argon2id hash made at the settings' cost."""
    cost = settings.password_cost
    return f"$argon2id$v=19$m={cost.memory_kib},t={cost.time_cost},p={cost.parallelism}$"


def _audit(settings, action=None):
    db = Database(settings.database_url)
    try:
        with db.read() as s:
            rows = s.query(AuditEntry).order_by(AuditEntry.id).all()
    finally:
        db.dispose()
    return [r for r in rows if action is None or r.action == action]


def test_login_sets_httponly_strict_session_and_readable_csrf_cookie(secured):
    r = _login(secured.client)
    assert r.status_code == 200, r.text
    assert r.json() == {"name": "alice", "role": "admin", "kind": "user", "language": None, "answered_in": "en"}
    cookies = {c.split("=", 1)[0]: c for c in r.headers.get_list("set-cookie")}
    session, csrf = cookies["trackvkf_session"], cookies["trackvkf_csrf"]
    assert "HttpOnly" in session and "samesite=strict" in session.lower()
    assert "HttpOnly" not in csrf and "samesite=strict" in csrf.lower()
    assert "Secure" not in session  # development over http; production sets Secure
    assert secured.client.get("/api/v1/auth/me").json()["name"] == "alice"
    # the session token is stored only as its digest
    token = secured.client.cookies["trackvkf_session"]
    db = Database(secured.settings.database_url)
    with db.read() as s:
        stored = s.execute(text("SELECT token_hash FROM sessions")).scalars().all()
    db.dispose()
    assert stored == [token_digest(token)] and token not in stored


def test_wrong_password_unknown_user_and_inactive_user_get_401(secured):
    assert _login(secured.client, password="wrong password!").status_code == 401
    assert _login(secured.client, username="mallory").status_code == 401
    secured.client.patch(
        "/api/v1/auth/users/vic", json={"active": False}, headers=secured.headers("admin")
    )
    assert _login(secured.client, username="vic").status_code == 401
    denied = [a for a in _audit(secured.settings, "auth.login") if a.outcome == "denied"]
    assert [a.target for a in denied] == ["alice", "mallory", "vic"]
    assert "trackvkf_session" not in secured.client.cookies


def test_logout_ends_the_session(secured):
    _login(secured.client)
    csrf = secured.client.cookies["trackvkf_csrf"]
    token = secured.client.cookies["trackvkf_session"]
    assert secured.client.post("/api/v1/auth/logout", headers={"X-CSRF-Token": csrf}).status_code == 204
    secured.client.cookies.set("trackvkf_session", token)  # replaying the old cookie
    assert secured.client.get("/api/v1/auth/me").status_code == 401


def test_expired_session_is_refused(tmp_path):
    from fastapi.testclient import TestClient

    from app.main import create_app

    settings = make_settings(tmp_path, session_ttl_s=0.001)
    migrate_database(settings.database_url)
    db = Database(settings.database_url)
    with db.write() as s:
        auth_crud.create_user(s, "alice", PASSWORD, "admin", password_cost=settings.password_cost)
    db.dispose()
    with TestClient(create_app(settings)) as client:
        assert _login(client).status_code == 200
        assert client.get("/api/v1/auth/me").status_code == 401


def test_login_rate_limit_per_user_name(secured):
    limit = secured.settings.login_rate_limit
    for _ in range(limit):
        assert _login(secured.client, password="wrong password!").status_code == 401
    r = _login(secured.client)  # even the right password is refused now
    assert r.status_code == 429
    assert int(r.headers["retry-after"]) >= 1
    assert r.json()["field"] == "rate_limit"


def test_upload_rate_limit_per_key(make_client, tmp_path):
    client = make_client(upload_rate_limit=2, upload_rate_window_s=3600)
    for i in range(2):
        path = runfiles.write_hdf5(tmp_path / f"r{i}.h5", data=runfiles.channels(seed=i))
        with open(path, "rb") as fh:
            assert client.post("/api/v1/runs", files={"file": (path.name, fh)}).status_code == 201
    path = runfiles.write_hdf5(tmp_path / "r9.h5", data=runfiles.channels(seed=9))
    with open(path, "rb") as fh:
        r = client.post("/api/v1/runs", files={"file": (path.name, fh)})
    assert r.status_code == 429 and "retry-after" in r.headers
    assert client.get("/api/v1/runs").json()["total"] == 2
    # another key has its own budget
    from tests.api.support import create_api_key

    other = create_api_key(client.settings.database_url, "engineer", "other")
    with open(path, "rb") as fh:
        r = client.post("/api/v1/runs", files={"file": (path.name, fh)}, headers=auth_headers(other))
    assert r.status_code == 201


def test_api_key_lifecycle_shown_once_hashed_last_used_revoked(secured):
    admin = secured.headers("admin")
    r = secured.client.post("/api/v1/auth/keys", json={"name": "ingest bot", "role": "engineer"}, headers=admin)
    assert r.status_code == 201, r.text
    created = r.json()
    key = created["key"]
    assert key.startswith(f"tvk_{created['prefix']}_") and created["last_used_at"] is None
    listed = secured.client.get("/api/v1/auth/keys", headers=admin).json()["items"]
    assert all("key" not in item for item in listed)
    db = Database(secured.settings.database_url)
    with db.read() as s:
        row = s.get(ApiKey, created["id"])
        assert row.key_hash == token_digest(key)
    # use it: last use is recorded, both header forms work
    assert secured.client.get("/api/v1/auth/me", headers={"X-API-Key": key}).json() == {
        "name": "key:ingest bot", "role": "engineer", "kind": "api_key", "language": None, "answered_in": "en",
    }
    assert secured.client.get("/api/v1/runs", headers=auth_headers(key)).status_code == 200
    item = next(i for i in secured.client.get("/api/v1/auth/keys", headers=admin).json()["items"] if i["id"] == created["id"])
    assert item["last_used_at"] is not None
    # revoke it
    assert secured.client.delete(f"/api/v1/auth/keys/{created['id']}", headers=admin).status_code == 204
    r = secured.client.get("/api/v1/runs", headers=auth_headers(key))
    assert r.status_code == 401 and r.headers["www-authenticate"].startswith("Bearer")
    actions = [(a.action, a.target) for a in _audit(secured.settings) if a.action.startswith("key.")]
    assert actions == [("key.create", str(created["id"])), ("key.revoke", str(created["id"]))]
    db.dispose()


@pytest.mark.parametrize(
    "header",
    [{"Authorization": "Bearer tvk_00000000_nope"}, {"Authorization": "Basic YWxpY2U6eA=="},
     {"X-API-Key": "x" * 5000}, {"Authorization": "Bearer "}],
)
def test_malformed_or_unknown_keys_get_401(secured, header):
    r = secured.client.get("/api/v1/runs", headers=header)
    assert r.status_code == 401


def test_expired_key_is_refused(secured):
    db = Database(secured.settings.database_url)
    with db.write() as s:
        _, key = auth_crud.create_api_key(
            s, "old", "viewer", expires_at=dt.datetime.now(dt.UTC) - dt.timedelta(seconds=1)
        )
    db.dispose()
    assert secured.client.get("/api/v1/runs", headers=auth_headers(key)).status_code == 401


def test_user_administration_and_password_change(secured):
    admin = secured.headers("admin")
    r = secured.client.post(
        "/api/v1/auth/users", json={"username": "otto", "password": "short", "role": "viewer"}, headers=admin
    )
    assert r.status_code == 422
    r = secured.client.post(
        "/api/v1/auth/users", json={"username": "otto", "password": "long enough pw", "role": "viewer"},
        headers=admin,
    )
    assert r.status_code == 201 and "password" not in r.text and "hash" not in r.text
    assert _stored_hash(secured, "otto").startswith(_parameters(secured.settings))  # the app's cost
    assert secured.client.post(
        "/api/v1/auth/users", json={"username": "otto", "password": "long enough pw", "role": "viewer"},
        headers=admin,
    ).status_code == 409
    assert _login(secured.client, "otto", "long enough pw").status_code == 200
    csrf = secured.client.cookies["trackvkf_csrf"]
    r = secured.client.post(
        "/api/v1/auth/password", json={"current_password": "wrong one!", "new_password": "another long pw"},
        headers={"X-CSRF-Token": csrf},
    )
    assert r.status_code == 401
    r = secured.client.post(
        "/api/v1/auth/password", json={"current_password": "long enough pw", "new_password": "another long pw"},
        headers={"X-CSRF-Token": csrf},
    )
    assert r.status_code == 204
    assert _stored_hash(secured, "otto").startswith(_parameters(secured.settings))
    assert secured.client.get("/api/v1/auth/me").status_code == 401  # sessions ended
    assert _login(secured.client, "otto", "another long pw").status_code == 200
    # role change takes effect, deletion removes the user
    secured.client.cookies.clear()
    r = secured.client.patch("/api/v1/auth/users/otto", json={"role": "engineer"}, headers=admin)
    assert r.status_code == 200 and r.json()["role"] == "engineer"
    assert secured.client.delete("/api/v1/auth/users/otto", headers=admin).status_code == 204
    assert secured.client.delete("/api/v1/auth/users/otto", headers=admin).status_code == 404
    assert _login(secured.client, "otto", "another long pw").status_code == 401
    actions = [a.action for a in _audit(secured.settings) if a.target == "otto"]
    assert actions == ["user.create", "auth.login", "auth.password", "auth.login", "user.update", "user.delete", "auth.login"]


def test_admin_cannot_lock_itself_out(secured):
    _login(secured.client)
    csrf = {"X-CSRF-Token": secured.client.cookies["trackvkf_csrf"]}
    assert secured.client.patch("/api/v1/auth/users/alice", json={"role": "viewer"}, headers=csrf).status_code == 409
    assert secured.client.delete("/api/v1/auth/users/alice", headers=csrf).status_code == 409


def test_audit_records_upload_reprocess_cancel_delete(secured, tmp_path):
    engineer, admin = secured.headers("engineer"), secured.headers("admin")
    path = runfiles.write_hdf5(tmp_path / "good.h5")
    with open(path, "rb") as fh:
        run = secured.client.post("/api/v1/runs", files={"file": (path.name, fh)}, headers=engineer).json()
    job_id = run["latest_job"]["id"]
    assert secured.client.post(f"/api/v1/jobs/{job_id}/cancel", headers=engineer).status_code == 200
    db = Database(secured.settings.database_url)
    with db.write() as s:  # the worker would mark it cancelled; do it here
        s.execute(text("UPDATE jobs SET status='cancelled' WHERE id=:i"), {"i": job_id})
    db.dispose()
    r = secured.client.post(f"/api/v1/runs/{run['id']}/jobs", json={"filter_order": 3}, headers=engineer)
    assert r.status_code == 201, r.text
    assert secured.client.delete(f"/api/v1/runs/{run['id']}", headers=admin).status_code == 204
    page = secured.client.get("/api/v1/audit", headers=admin, params={"limit": 50}).json()
    entries = [(e["action"], e["actor"], e["target"]) for e in reversed(page["items"])]
    assert entries == [
        ("run.upload", "key:test-engineer", str(run["id"])),
        ("job.cancel", "key:test-engineer", str(job_id)),
        ("job.create", "key:test-engineer", str(run["id"])),
        ("run.delete", "key:test-admin", str(run["id"])),
    ]
    upload = page["items"][-1]
    assert upload["detail"]["sha256"] == run["sha256"] and upload["outcome"] == "ok"
    only = secured.client.get("/api/v1/audit", headers=admin, params={"action": "run.delete"}).json()
    assert only["total"] == 1
    assert secured.client.get("/api/v1/audit", headers=admin, params={"since": "yesterday"}).status_code == 422


def test_audit_log_is_append_only_in_the_database(secured):
    db = Database(secured.settings.database_url)
    with db.write() as s:
        auth_crud.audit(s, actor="x", actor_kind="user", action="auth.login")
    for statement in ("UPDATE audit_log SET actor='y'", "DELETE FROM audit_log"):
        with pytest.raises(DatabaseError, match="append-only"), db.write() as s:
            s.execute(text(statement))
    with db.read() as s:
        assert s.execute(text("SELECT actor FROM audit_log")).scalars().all() == ["x"]
    db.dispose()


def test_login_page_and_docs(secured):
    page = secured.client.get("/login", params={"next": "/runs/3?wheel=11"})
    assert page.status_code == 200 and "text/html" in page.headers["content-type"]
    assert 'data-next="/runs/3?wheel=11"' in page.text
    assert page.headers["x-frame-options"] == "DENY"
    for hostile in ("//evil.example/x", "https://evil.example", "/\\evil", "javascript:alert(1)"):
        assert 'data-next="/"' in secured.client.get("/login", params={"next": hostile}).text
    hostile = secured.client.get("/login", params={"next": '"><script>'}).text
    assert "<script>" not in hostile and hostile.count("<script") == 2  # only the page's catalogue and login.js
    r = secured.client.get("/docs")
    assert r.status_code == 303 and r.headers["location"] == "/login?next=%2Fdocs"
    assert secured.client.get("/openapi.json").status_code == 401
    assert secured.client.get("/api/v1/health").status_code == 200
    schema = secured.client.get("/openapi.json", headers=secured.headers("viewer")).json()
    assert schema["components"]["securitySchemes"]["bearerKey"]["scheme"] == "bearer"
    assert schema["paths"]["/api/v1/health"]["get"]["security"] == []


@pytest.mark.parametrize(
    "url",
    [
        "/api/v1/runs?date_to=9999-12-31T23:59:59-14:00",
        "/api/v1/runs?date_from=0001-01-01T00:00:00%2B14:00",
        "/api/v1/audit?since=9999-12-31T23:59:59-14:00",
        "/api/v1/audit?until=0001-01-01T00:00:00%2B14:00",
        "/api/v1/runs?limit=100000000000000000000000000",
        "/api/v1/runs/1/profile?wheel=11&level=nan",
        "/api/v1/runs/1/profile?wheel=11&km_from=inf",
        "/api/v1/jobs?run_id=99999999999999999999",
        "/api/v1/audit?limit=0",
    ],
)
def test_out_of_range_query_parameters_are_422_not_500(secured, url):
    r = secured.client.get(url, headers=secured.headers("admin"))
    assert r.status_code == 422, r.text


def test_docs_page_serves_swagger_ui_locally(secured):
    """Swagger UI's script and style come from the app itself (closed network), not a CDN."""
    import re

    page = secured.client.get("/docs", headers=secured.headers("viewer"))
    assert page.status_code == 200, page.text
    urls = re.findall(r"""(?:src|href|url)\s*[=:]\s*['"]([^'"]+)['"]""", page.text)
    assert any(u.endswith("swagger-ui-bundle.js") for u in urls), urls
    assert not [u for u in urls if "://" in u or u.startswith("//")], urls
    for asset in [u for u in urls if u.startswith("/docs-assets/")]:
        assert secured.client.get(asset).status_code == 200, asset
