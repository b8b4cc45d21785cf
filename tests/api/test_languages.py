"""The service in four languages over HTTP: error texts in the request's language (the user's
choice kept with the account, else Accept-Language) with the machine-readable field unchanged,
the language kept with the account (PATCH /auth/me), the pages and the login page in it, and the
pages' script catalogue."""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient

from app.db import auth_crud
from app.db.session import Database
from app.main import create_app
from tests.api.support import auth_headers, create_api_key, make_settings, migrate_database

PASSWORD = "languages test password"


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    settings = make_settings(tmp_path_factory.mktemp("languages"), login_rate_limit=100_000)
    migrate_database(settings.database_url)
    key = create_api_key(settings.database_url, "viewer")
    db = Database(settings.database_url)
    with db.write() as session:
        auth_crud.create_user(session, "hanna", PASSWORD, "engineer", password_cost=settings.password_cost)
    db.dispose()
    with TestClient(create_app(settings), follow_redirects=False) as client:
        yield client, key


def _login(client: TestClient) -> dict[str, str]:
    client.cookies.clear()
    r = client.post("/api/v1/auth/login", json={"username": "hanna", "password": PASSWORD})
    assert r.status_code == 200, r.text
    return {"X-CSRF-Token": client.cookies["trackvkf_csrf"]}


@pytest.mark.parametrize(("lang", "text"), [
    (None, "run 999 not found"), ("en-GB", "run 999 not found"), ("de-CH,de;q=0.9", "Messfahrt 999 nicht gefunden"),
    ("fr", "parcours 999 introuvable"), ("it-IT", "corsa 999 non trovata"),
])
def test_errors_in_the_browsers_language(service, lang, text):
    client, key = service
    client.cookies.clear()
    headers = auth_headers(key) | ({"Accept-Language": lang} if lang else {})
    r = client.get("/api/v1/runs/999", headers=headers)
    assert r.status_code == 404
    assert r.json() == {"detail": f"run_id: {text}", "field": "run_id"}


def test_validation_and_routing_errors_translated(service):
    client, key = service
    client.cookies.clear()
    de = auth_headers(key) | {"Accept-Language": "de"}
    r = client.get("/api/v1/runs", params={"limit": "abc"}, headers=de)
    assert r.status_code == 422 and r.json()["field"] == "limit"
    assert r.json()["detail"].startswith("limit: muss eine ganze Zahl sein (erhalten: 'abc')"), r.json()
    en = client.get("/api/v1/runs", params={"limit": "abc"}, headers=auth_headers(key)).json()["detail"]
    assert en.startswith("limit: Input should be a valid integer")  # English keeps pydantic's words
    r = client.get("/api/v1/no-such-thing", headers=de | {"Accept-Language": "it"})
    assert r.status_code == 404 and r.json()["detail"] == "path: percorso inesistente '/api/v1/no-such-thing'"
    r = client.get("/api/v1/runs/1", headers={"Accept-Language": "fr"})  # no credentials
    assert r.status_code == 401 and r.json()["field"] == "authentication"


def test_the_language_is_kept_with_the_account(service):
    client, key = service
    csrf = _login(client)
    me = client.get("/api/v1/auth/me", headers={"Accept-Language": "fr"}).json()
    assert me["language"] is None and me["answered_in"] == "fr"
    r = client.patch("/api/v1/auth/me", json={"language": "it"}, headers=csrf | {"Accept-Language": "fr"})
    assert r.status_code == 200 and r.json()["language"] == "it" and r.json()["answered_in"] == "it"
    # the account's language wins over the browser's, in errors and pages; it survives a new login
    csrf = _login(client)
    r = client.get("/api/v1/runs/999", headers={"Accept-Language": "de"})
    assert r.json()["detail"] == "run_id: corsa 999 non trovata"
    page = client.get("/", headers={"Accept-Language": "de"})
    assert page.status_code == 200 and '<html lang="it">' in page.text and ">Corse</a>" in page.text
    assert '<option value="it" lang="it" translate="no" selected>' in page.text
    bad = client.patch("/api/v1/auth/me", json={"language": "klingon"}, headers=csrf)
    assert bad.status_code == 422 and bad.json()["field"] == "language"
    assert client.patch("/api/v1/auth/me", json={"language": None}, headers=csrf).json()["language"] is None
    assert client.get("/api/v1/runs/999", headers={"Accept-Language": "de"}).json()["detail"].startswith("run_id: Messfahrt")
    client.cookies.clear()
    r = client.patch("/api/v1/auth/me", json={"language": "de"}, headers=auth_headers(key))
    assert r.status_code == 409 and r.json()["field"] == "principal"


def test_pages_and_login_in_the_browsers_language(service):
    client, _key = service
    client.cookies.clear()
    login = client.get("/login", headers={"Accept-Language": "fr-CH"})
    assert '<html lang="fr">' in login.text and "Mot de passe" in login.text and "Password<" not in login.text
    script = re.search(r'<script src="(/i18n/fr\.js\?v=\w+)"></script>', login.text)
    assert script, login.text
    js = client.get(script.group(1))
    assert js.status_code == 200 and js.headers["content-type"].startswith("text/javascript")
    assert "Wrong user name or password." in js.text and "Nom d'utilisateur ou mot de passe incorrect." in js.text
    assert client.get("/i18n/xx.js").status_code in (404, 422)
    _login(client)
    page = client.get("/", headers={"Accept-Language": "de-CH"})
    assert '<html lang="de">' in page.text and "Messfahrt hochladen" in page.text
    assert '"locale": "de-CH"' in page.text and '"decimal": "."' in page.text  # Swiss German numbers
    assert '"lang": "de"' in page.text and '"tamping": "Stopfen"' in page.text


def test_every_code_the_pages_show_has_its_words():
    """Each value of the enumerations the pages show (tiers, statuses, types, ...) has words in
    every language: the vocabulary is made from the enumerations, a new code without words fails."""
    from app.web import vocabulary

    english = vocabulary.messages()
    for lang in ("de", "fr", "it"):
        words = vocabulary.labels(lang)
        for kind, codes in english.items():
            assert set(words[kind]) == set(codes), kind
            assert all(words[kind].values()), (lang, kind)
    assert vocabulary.labels("de")["maintenance type"]["tamping"] == "Stopfen"
    assert vocabulary.labels("fr")["asset type"]["weld"] == "soudure"
    assert vocabulary.labels("it")["maintenance type"]["tamping"] == "rincalzatura"
