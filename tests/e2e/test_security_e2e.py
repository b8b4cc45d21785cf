"""Access control on the real service (uvicorn over HTTP) with users and keys made by the CLI."""

from __future__ import annotations

import httpx
import pytest
from typer.testing import CliRunner

from app.cli import app
from app.cli.demo import _demo_credentials
from app.db import auth_crud
from app.db.session import Database
from app.settings import get_settings
from tests.api import runfiles

pytestmark = pytest.mark.timeout(300)

runner = CliRunner()


@pytest.fixture
def cli_env(service, monkeypatch):
    """The CLI pointed at the service's database."""
    monkeypatch.setenv("TRACKVKF_DATABASE_URL", service.database_url)
    monkeypatch.setenv("TRACKVKF_RUN_STORE", str(service.run_store))
    get_settings.cache_clear()
    yield service
    get_settings.cache_clear()


def test_cli_key_and_user_work_over_http(cli_env, tmp_path):
    service = cli_env
    with httpx.Client(base_url=service.base_url, timeout=60) as anon:
        r = anon.get("/api/v1/runs")
        assert r.status_code == 401 and r.headers["www-authenticate"].startswith("Bearer")
        assert anon.get("/api/v1/health").status_code == 200
        assert anon.get("/docs", follow_redirects=False).headers["location"] == "/login?next=%2Fdocs"

    result = runner.invoke(app, ["key", "create", "loader", "--role", "engineer"])
    assert result.exit_code == 0, result.output
    key = result.stdout.strip().splitlines()[-1]
    assert key.startswith("tvk_")
    path = runfiles.write_hdf5(tmp_path / "good.h5")
    with httpx.Client(base_url=service.base_url, headers={"X-API-Key": key}, timeout=60) as loader:
        with open(path, "rb") as fh:
            r = loader.post("/api/v1/runs", files={"file": (path.name, fh)})
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        assert loader.delete(f"/api/v1/runs/{run_id}").status_code == 403

    result = runner.invoke(app, ["user", "create", "vera", "--role", "viewer", "--generate"])
    assert result.exit_code == 0, result.output
    password = result.stdout.split("password: ")[1].strip()
    with httpx.Client(base_url=service.base_url, timeout=60) as browser:
        r = browser.post("/api/v1/auth/login", json={"username": "vera", "password": password})
        assert r.status_code == 200, r.text
        assert browser.get(f"/api/v1/runs/{run_id}").status_code == 200
        csrf = {"X-CSRF-Token": browser.cookies["trackvkf_csrf"]}
        assert browser.post(f"/api/v1/runs/{run_id}/jobs", json={}, headers=csrf).status_code == 403
        assert browser.get("/docs").status_code == 200
        assert browser.post("/api/v1/auth/logout", headers=csrf).status_code == 204
        assert browser.get("/api/v1/auth/me").status_code == 401

    result = runner.invoke(app, ["key", "list"])
    assert "loader" in result.output and "last used 20" in result.output
    key_id = next(line.split("\t")[0] for line in result.output.splitlines() if "loader" in line)
    assert runner.invoke(app, ["key", "revoke", key_id]).exit_code == 0
    r = httpx.get(f"{service.base_url}/api/v1/runs", headers={"X-API-Key": key})
    assert r.status_code == 401
    with service.client(timeout=60) as admin:
        actions = [e["action"] for e in admin.get("/api/v1/audit").json()["items"]]
    assert {"key.create", "key.revoke", "user.create", "run.upload", "auth.login", "auth.logout"} <= set(actions)


def test_demo_admin_created_once_and_production_refuses_it(tmp_path, monkeypatch):
    url = f"sqlite:///{tmp_path / 'demo.sqlite'}"
    from app.db import migrate

    migrate.upgrade(url)
    monkeypatch.setenv("TRACKVKF_DATABASE_URL", url)
    get_settings.cache_clear()
    try:
        password, key, _ = _demo_credentials(get_settings())
        again, _, _ = _demo_credentials(get_settings())
        assert password and again is None and key.startswith("tvk_")
        db = Database(url)
        with db.read() as s:
            admin = auth_crud.get_user(s, "admin")
            assert admin.role == "admin" and admin.demo_credentials
            from app.core.security import verify_password

            assert verify_password(admin.password_hash, password)
        db.dispose()

        monkeypatch.setenv("TRACKVKF_ENV", "production")
        get_settings.cache_clear()
        result = runner.invoke(app, ["serve"])
        assert result.exit_code == 2 and "TRACKVKF_SECRET_KEY" in result.output
        monkeypatch.setenv("TRACKVKF_SECRET_KEY", "s" * 40)
        get_settings.cache_clear()
        result = runner.invoke(app, ["serve"])
        assert result.exit_code == 2 and "default credentials" in result.output
        result = runner.invoke(app, ["demo"])
        assert result.exit_code == 2 and "production" in result.output
    finally:
        get_settings.cache_clear()
