"""Security headers on every page, API answer and static file (issue 18, item 6).

Before: only ``/login`` and ``/docs`` had them. The browser tests
(``tests/dashboard``) show the pages working under the policy: no console
errors (a CSP violation is one) on any page.
"""

from __future__ import annotations

import re

import pytest

from app.api.headers import CONTENT_SECURITY_POLICY, inline_script_hashes
from tests.security.conftest import PASSWORD

EXPECTED = {
    "x-frame-options": "DENY",
    "x-content-type-options": "nosniff",
    "referrer-policy": "same-origin",
}

URLS = [
    ("/login", None),
    ("/", None),  # 303 to the login page
    ("/runs/1", "cookie"),  # a dashboard page
    ("/api/v1/health", None),
    ("/api/v1/runs", None),  # 401
    ("/api/v1/runs", "viewer"),
    ("/api/v1/runs/999", "viewer"),  # 404
    ("/api/v1/runs?limit=0", "viewer"),  # 422
    ("/api/v1/audit", "viewer"),  # 403
    ("/api/v1/no-such-route", "viewer"),  # 404 of the router
    ("/openapi.json", "viewer"),
    ("/static/js/api.js", None),
    ("/static/css/app.css", None),
    ("/vendor/plotly.min.js", "cookie"),
    ("/docs-assets/swagger-ui.css", None),
]


def _headers(secured, who):
    if who == "cookie":
        r = secured.client.post("/api/v1/auth/login", json={"username": "vic", "password": PASSWORD})
        assert r.status_code == 200
        return {}
    return secured.headers(who)


@pytest.mark.parametrize(("url", "who"), URLS)
def test_every_answer_carries_the_security_headers(secured, url, who):
    r = secured.client.get(url, headers=_headers(secured, who))
    assert r.status_code < 500
    for name, value in EXPECTED.items():
        assert r.headers.get(name) == value, (url, r.status_code, name)
    assert r.headers["content-security-policy"] == CONTENT_SECURITY_POLICY


def test_policy_forbids_inline_and_foreign_scripts_and_framing():
    directives = dict(d.strip().split(" ", 1) for d in CONTENT_SECURITY_POLICY.split(";"))
    assert directives["script-src"] == "'self'"
    assert directives["frame-ancestors"] == "'none'"
    assert directives["object-src"] == "'none'"
    assert directives["default-src"] == "'self'"
    assert "unsafe-eval" not in CONTENT_SECURITY_POLICY


def test_pages_have_no_inline_scripts(secured):
    """Only data blocks (type=application/json) may stand inline; code comes from files."""
    _headers(secured, "cookie")
    for url in ("/login", "/", "/lines", "/wheels", "/correlations"):
        r = secured.client.get(url)
        assert r.status_code == 200, url
        scripts = re.findall(r"<script([^>]*)>(.*?)</script>", r.text, re.DOTALL)
        for attrs, body in scripts:
            assert "src=" in attrs or 'type="application/json"' in attrs, (url, attrs, body[:80])


def test_swagger_page_allows_exactly_its_own_inline_script(secured):
    _headers(secured, "cookie")
    r = secured.client.get("/docs")
    assert r.status_code == 200
    csp = r.headers["content-security-policy"]
    hashes = inline_script_hashes(r.text)
    assert len(hashes) == 1
    assert f"script-src 'self' {hashes[0]};" in csp
    assert r.headers["x-frame-options"] == "DENY"

