"""Apps built in one process share the analysed routes (app.main.app_routes), never their state:
each answers with its own settings, database and key."""

from __future__ import annotations

from fastapi.testclient import TestClient

from app.main import app_routes, create_app
from tests.api.support import auth_headers, create_api_key, make_settings, migrate_database


def test_apps_share_the_routes_and_answer_with_their_own_settings(tmp_path):
    clients = {}
    for name, page in (("a", 7), ("b", 9)):
        settings = make_settings(tmp_path / name, max_page_size=page)
        migrate_database(settings.database_url)
        key = create_api_key(settings.database_url, "viewer")
        clients[name] = (create_app(settings), key)
    (app_a, key_a), (app_b, key_b) = clients["a"], clients["b"]
    shared = app_routes()
    ids_a, ids_b = {id(r) for r in app_a.routes}, {id(r) for r in app_b.routes}
    assert shared and all(id(route) in ids_a and id(route) in ids_b for route in shared)
    assert app_a.routes is not app_b.routes
    with TestClient(app_a) as a, TestClient(app_b) as b:
        # the settings of the app that answers: a page of 8 is too large for a (<= 7), not for b (<= 9)
        r = a.get("/api/v1/runs?limit=8", headers=auth_headers(key_a))
        assert r.status_code == 422 and r.json()["field"] == "limit" and "7" in r.text, r.text
        assert b.get("/api/v1/runs?limit=8", headers=auth_headers(key_b)).status_code == 200
        # and its own database: a key of one is unknown to the other
        assert a.get("/api/v1/runs?limit=5", headers=auth_headers(key_b)).status_code == 401
        assert b.get("/api/v1/runs?limit=5", headers=auth_headers(key_b)).status_code == 200
        # a route added to one app is not added to the other
        app_a.add_api_route("/api/v1/only-a", lambda: {"app": "a"}, methods=["GET"])
        assert a.get("/api/v1/only-a").json() == {"app": "a"}
        assert b.get("/api/v1/only-a", headers=auth_headers(key_b)).status_code == 404
        paths_a = a.get("/openapi.json", headers=auth_headers(key_a)).json()["paths"].keys()
        paths_b = b.get("/openapi.json", headers=auth_headers(key_b)).json()["paths"].keys()
        assert set(paths_a) == {*paths_b, "/api/v1/only-a"} and "/api/v1/runs" in paths_b
