"""Logins under attack (issue 18, items 3 and 4).

* Item 3: a failed login held SQLite's write lock while Argon2 verified the
  password (4 failing login loops kept the lock busy 98 % of the time). The
  password must be verified outside any write transaction.
* Item 4: 10 wrong passwords from any address locked the user out (a per-name
  limit). Brute force is now limited per (address, name), per address, and by a
  per-name failure budget that browsers which logged in as the user before
  (device cookie) are exempt from; re-login from a browser ends its old session.
"""

from __future__ import annotations

import contextlib
import sqlite3
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

import app.accounts.sessions as accounts_sessions
from app.core.security import device_cookie_id, new_device_cookie
from app.db import auth_crud
from app.db.models import AuditEntry
from app.db.session import Database
from app.main import create_app
from tests.api.support import make_settings, migrate_database
from tests.security.conftest import PASSWORD

LOGIN = "/api/v1/auth/login"


def _login(client: TestClient, username: str = "alice", password: str = PASSWORD):
    return client.post(LOGIN, json={"username": username, "password": password})


@pytest.fixture
def service(tmp_path: Path):
    """Factory of apps on one migrated SQLite database holding the admin ``alice``."""
    settings = make_settings(tmp_path)
    migrate_database(settings.database_url)
    db = Database(settings.database_url)
    with db.write() as session:
        auth_crud.create_user(session, "alice", PASSWORD, "admin", password_cost=settings.password_cost)
    db.dispose()
    with contextlib.ExitStack() as running:

        def make(address: str = "10.0.0.1", **overrides) -> TestClient:
            """A started app with ``overrides`` of the settings and a client from ``address``."""
            settings = make_settings(tmp_path, **overrides)
            client = running.enter_context(TestClient(create_app(settings), client=(address, 50000)))
            client.app_settings = settings  # type: ignore[attr-defined]
            return client

        yield make


def _browser(client: TestClient, address: str) -> TestClient:
    """Another browser (no cookies) on the same app, from ``address`` (lifespan not run again)."""
    return TestClient(client.app, client=(address, 50001))


# --- item 3: no write lock while Argon2 runs ---------------------------------------------
def _probe_write_lock(db_file: Path, seen: list[str]):
    """A verify_password that first writes to the database from another connection, never waiting."""
    original = accounts_sessions.verify_password

    def verify(password_hash: str, password: str) -> bool:
        conn = sqlite3.connect(db_file, timeout=0)  # no busy wait: a held write lock fails at once
        try:
            conn.execute("BEGIN IMMEDIATE")
            conn.execute("CREATE TABLE IF NOT EXISTS probe (x INTEGER)")
            conn.execute("INSERT INTO probe VALUES (1)")
            conn.execute("COMMIT")
            seen.append("free")
        except sqlite3.OperationalError as exc:
            seen.append(f"locked: {exc}")
        finally:
            conn.close()
        return original(password_hash, password)

    return verify


@pytest.mark.parametrize("password", ["wrong password!", PASSWORD], ids=["failed", "successful"])
def test_login_verifies_the_password_while_other_writers_can_write(service, tmp_path, monkeypatch, password):
    client = service()
    seen: list[str] = []
    monkeypatch.setattr(accounts_sessions, "verify_password", _probe_write_lock(tmp_path / "db.sqlite", seen))
    r = _login(client, password=password)
    assert r.status_code == (200 if password == PASSWORD else 401)
    assert seen == ["free"]
    # and the attempt is audited all the same, in its own short transaction
    db = Database(client.app_settings.database_url)
    with db.read() as session:
        outcomes = [e.outcome for e in session.query(AuditEntry).filter_by(action="auth.login")]
    db.dispose()
    assert outcomes == ["ok" if password == PASSWORD else "denied"]


def test_unknown_user_and_password_change_verify_outside_the_write_transaction(service, tmp_path, monkeypatch):
    client = service()
    assert _login(client).status_code == 200
    seen: list[str] = []
    monkeypatch.setattr(accounts_sessions, "verify_password", _probe_write_lock(tmp_path / "db.sqlite", seen))
    assert _login(client, username="nobody").status_code == 401
    r = client.post(
        "/api/v1/auth/password",
        json={"current_password": PASSWORD, "new_password": "another good password"},
        headers={"X-CSRF-Token": client.cookies.get("trackvkf_csrf")},
    )
    assert r.status_code == 204, r.text
    assert seen == ["free", "free"]


def test_an_unknown_user_name_is_verified_at_the_cost_of_the_known_ones(service, monkeypatch):
    """A login of a name that does not exist verifies the password against a hash of the configured
    cost: it takes as long as a wrong password of a real user (the time does not tell which names
    exist)."""
    client = service()
    verified: list[str] = []
    original = accounts_sessions.verify_password

    def record_hash(password_hash: str, password: str) -> bool:
        verified.append(password_hash)
        return original(password_hash, password)

    monkeypatch.setattr(accounts_sessions, "verify_password", record_hash)
    assert _login(client, password="wrong password!").status_code == 401
    assert _login(client, username="nobody").status_code == 401
    cost = client.app_settings.password_cost
    parameters = f"$argon2id$v=19$m={cost.memory_kib},t={cost.time_cost},p={cost.parallelism}$"
    assert len(verified) == 2 and all(h.startswith(parameters) for h in verified), verified


# --- item 4: no lockout lever ---------------------------------------------------------------
def test_wrong_passwords_from_one_address_do_not_lock_out_other_addresses(service):
    attacker = service("10.6.6.6")
    limit = attacker.app_settings.login_rate_limit
    for _ in range(limit):
        assert _login(attacker, password="wrong password!").status_code == 401
    r = _login(attacker)
    assert r.status_code == 429 and r.json()["field"] == "rate_limit"
    user = _browser(attacker, "10.0.0.7")
    assert _login(user).status_code == 200


def test_address_limit_counts_attempts_on_all_names(service):
    sprayer = service("10.6.6.6", login_address_rate_limit=3)
    for name in ("alice", "bob", "carol"):
        assert _login(sprayer, username=name, password="wrong password!").status_code == 401
    assert _login(sprayer, username="dave").status_code == 429
    user = _browser(sprayer, "10.0.0.7")
    assert _login(user).status_code == 200


def test_name_failure_budget_stops_distributed_guessing_but_not_the_users_browser(service):
    browser = service("10.0.0.1", login_name_failure_limit=3)
    assert _login(browser).status_code == 200  # the user's own browser gets the device cookie
    assert any(c.name == "trackvkf_device" for c in browser.cookies.jar)
    for i in range(3):  # a botnet: one guess per address
        bot = _browser(browser, f"10.9.0.{i}")
        assert _login(bot, password="wrong password!").status_code == 401
    bot = _browser(browser, "10.9.0.99")  # the budget is spent: even a right guess is refused
    r = _login(bot)
    assert r.status_code == 429 and r.json()["field"] == "rate_limit"
    new_browser = _browser(browser, "10.0.0.1")  # the user's address without the cookie too
    assert _login(new_browser).status_code == 429
    assert _login(browser).status_code == 200  # the browser that logged in before still can
    # refused attempts are not audited (a flood must not grow the log); the failures are
    db = Database(browser.app_settings.database_url)
    with db.read() as session:
        outcomes = [e.outcome for e in session.query(AuditEntry).filter_by(action="auth.login")]
    db.dispose()
    assert outcomes == ["ok", "denied", "denied", "denied", "ok"]


def test_device_cookie_of_another_user_or_a_forged_one_does_not_exempt(service):
    browser = service("10.0.0.1", login_name_failure_limit=1)
    settings = browser.app_settings
    bot = _browser(browser, "10.9.0.1")
    assert _login(bot, password="wrong password!").status_code == 401
    for value in (new_device_cookie(settings.secret_key, "mallory"), new_device_cookie("x" * 40, "alice"),
                  "abc.def", "garbage"):
        bot = _browser(browser, "10.9.0.2")
        bot.cookies.set("trackvkf_device", value, path=LOGIN)
        assert _login(bot).status_code == 429, value


def test_device_cookie_is_bound_to_secret_and_name():
    cookie = new_device_cookie("s" * 40, "alice")
    assert device_cookie_id("s" * 40, cookie, "alice") == cookie.split(".")[0]
    assert device_cookie_id("s" * 40, cookie, "bob") is None
    assert device_cookie_id("t" * 40, cookie, "alice") is None
    assert device_cookie_id("s" * 40, None, "alice") is None
    assert device_cookie_id("s" * 40, cookie + "0", "alice") is None


def test_login_again_from_the_same_browser_ends_the_old_session(service):
    browser = service()
    assert _login(browser).status_code == 200
    old = browser.cookies.get("trackvkf_session")
    assert _login(browser).status_code == 200
    new = browser.cookies.get("trackvkf_session")
    assert new and new != old
    assert browser.get("/api/v1/auth/me").status_code == 200
    replay = _browser(browser, "10.0.0.1")
    replay.cookies.set("trackvkf_session", old)
    assert replay.get("/api/v1/auth/me").status_code == 401
