"""Corporate sign-in in the browser: Debian's chromium (Playwright) signs in at the real test
provider and back, goes to the page it asked for, signs out at the provider too; a user without
access and a provider that is down get a page that says so."""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest

from tests.dashboard.conftest import SCREENSHOTS
from tests.e2e.conftest import running_service
from tests.oidc.conftest import PASSWORDS, PROVIDER_NAME, oidc_env


@pytest.fixture
def page(browser, oidc):
    ctx = browser.new_context(base_url=oidc.base_url, viewport={"width": 1200, "height": 800})
    ctx.set_default_timeout(30_000)
    errors: list[str] = []
    p = ctx.new_page()
    p.on("pageerror", lambda e: errors.append(str(e)))
    try:
        yield p
    finally:
        ctx.close()
    assert not errors, errors


def _shot(page, name: str) -> Path:
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    path = SCREENSHOTS / f"oidc-{name}.png"
    page.screenshot(path=str(path))
    return path


def _sign_in_at_provider(page, username: str) -> None:
    page.goto("/condition")  # not logged in: the login page, with the way back
    assert "/login?next=" in page.url
    button = page.locator("#oidc-signin")
    assert button.inner_text() == f"Sign in with {PROVIDER_NAME}"
    _shot(page, "login")
    button.click()
    page.wait_for_selector("#op-username")  # the provider's own login form
    page.fill("#op-username", username)
    page.fill("#op-password", PASSWORDS[username])
    page.click("#op-submit")


def test_sign_in_and_out_through_the_provider(page, oidc):
    _sign_in_at_provider(page, "alice")
    page.wait_for_url(f"{oidc.base_url}/condition")  # the page asked for, through the callback
    page.wait_for_selector("#logout")
    me = page.request.get("/api/v1/auth/me")
    assert me.status == 200 and me.json() == {"name": "alice", "role": "engineer", "kind": "user",
                                              "language": None, "answered_in": "en"}
    _shot(page, "signed-in")
    before = len(oidc.provider.logouts)
    page.click("#logout")
    page.wait_for_url(f"{oidc.base_url}/login")  # back from the provider's sign-out
    assert len(oidc.provider.logouts) == before + 1
    assert oidc.provider.logouts[-1]["preferred_username"] == "alice"
    assert page.request.get("/api/v1/auth/me").status == 401


def test_a_user_without_access_gets_a_page_that_says_so(page, oidc):
    _sign_in_at_provider(page, "carol")
    page.wait_for_selector("#signin-title")
    assert page.inner_text("#signin-title") == "No access"
    assert "carol is in none of the groups" in page.inner_text("#signin-detail")
    _shot(page, "no-access")
    page.click("#signin-back")
    page.wait_for_url(f"{oidc.base_url}/login")


def test_a_provider_that_is_down_gets_a_clear_page(browser, tmp_path):
    with socket.socket() as sock:  # a port nobody listens on
        sock.bind(("127.0.0.1", 0))
        issuer = f"http://127.0.0.1:{sock.getsockname()[1]}"
    with running_service(tmp_path, env_overrides=oidc_env(issuer)) as svc:
        ctx = browser.new_context(base_url=svc.base_url)
        try:
            p = ctx.new_page()
            p.goto("/login")
            p.click("#oidc-signin")
            p.wait_for_selector("#signin-title")
            assert p.inner_text("#signin-title") == "Sign-in unavailable"
            assert "provider cannot be reached" in p.inner_text("#signin-message")
            assert issuer in p.inner_text("#signin-detail")
            _shot(p, "provider-down")
            p.click("#signin-back")
            p.wait_for_url(f"{svc.base_url}/login")
            # local accounts still log in
            assert p.locator("#username").is_visible()
        finally:
            ctx.close()
    assert os.environ.get("TRACKVKF_OIDC_ISSUER") is None  # nothing leaked into the test process
