"""The pages under the Content-Security-Policy (issue 18, item 6), in real Chromium.

The policy forbids inline scripts: the login form and Swagger UI must still
work, and a violation must show up as a console error (which every page test
asserts there is none of).
"""

from __future__ import annotations

import pytest

from tests.dashboard.conftest import PASSWORD, USER, PageLog

pytestmark = pytest.mark.timeout(300)


def test_login_form_works_under_the_policy(browser, dashboard):
    ctx = browser.new_context(base_url=dashboard.base_url)
    try:
        page = ctx.new_page()
        log = PageLog(origin=dashboard.base_url)
        log.attach(page)
        page.goto("/login?next=/wheels")
        page.fill("#username", USER)
        page.fill("#password", "not the password")
        page.click("button[type=submit]")
        page.wait_for_selector("#error:not(:empty)")
        assert "Wrong user name or password" in page.inner_text("#error")
        page.fill("#password", PASSWORD)
        page.click("button[type=submit]")
        page.wait_for_url(f"{dashboard.base_url}/wheels")
        page.wait_for_selector("body[data-ready='1']")
        # the wrong password's 401 is a console error of its own; no policy violation, no script error
        assert not [e for e in log.console_errors if "Content Security Policy" in e], log.console_errors
        assert not log.page_errors
    finally:
        ctx.close()


def test_swagger_ui_runs_under_the_policy(context, dashboard):
    """The page's inline setup script runs (allowed by its hash): Swagger UI renders into the page."""
    page = context.new_page()
    log = PageLog(origin=dashboard.base_url)
    log.attach(page)
    page.goto("/docs")
    page.wait_for_selector("#swagger-ui .swagger-ui", state="attached")  # rendered by SwaggerUIBundle
    page.wait_for_load_state("networkidle")
    assert any(u.endswith("/openapi.json") for u in log.requests)
    log.assert_clean()


def test_a_policy_violation_is_a_console_error(open_page):
    page, log = open_page("/")
    assert not log.console_errors
    page.evaluate("""() => { const s = document.createElement('script');
        s.textContent = 'window.injected = 1'; document.body.appendChild(s); }""")
    page.wait_for_timeout(300)
    assert page.evaluate("() => window.injected") is None  # refused
    assert any("Content Security Policy" in e for e in log.console_errors), log.console_errors
