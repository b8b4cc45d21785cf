"""``trackvkf serve --workers N``: several API processes, by default one per core."""

from __future__ import annotations

import os

import pytest
import uvicorn
from typer.testing import CliRunner

from app.cli import app
from app.cli.service import default_api_workers
from app.db import migrate
from app.settings import get_settings


@pytest.fixture
def started(monkeypatch, tmp_path):
    calls: list[dict] = []
    monkeypatch.setattr(uvicorn, "run", lambda *a, **kw: calls.append({"args": a, **kw}))
    url = f"sqlite:///{tmp_path / 'db.sqlite'}"
    migrate.upgrade(url)  # serve refuses a database that does not exist
    monkeypatch.setenv("TRACKVKF_DATABASE_URL", url)
    get_settings.cache_clear()
    yield calls
    get_settings.cache_clear()


def test_serve_starts_the_asked_number_of_processes(started):
    result = CliRunner().invoke(app, ["serve", "--workers", "3", "--port", "8123"])
    assert result.exit_code == 0, result.output
    (call,) = started
    assert call["workers"] == 3 and call["port"] == 8123 and call["factory"] is True
    assert call["args"] == ("app.main:create_app",)  # an import string: required for several processes


def test_serve_defaults_to_one_process_per_usable_core(started):
    assert CliRunner().invoke(app, ["serve"]).exit_code == 0
    assert started[0]["workers"] == default_api_workers() == len(os.sched_getaffinity(0))


def test_serve_refuses_zero_workers(started):
    result = CliRunner().invoke(app, ["serve", "--workers", "0"])
    assert result.exit_code == 2 and not started


def test_serve_leaves_no_metrics_directory_behind_in_the_environment(started, monkeypatch):
    """``serve`` makes a metrics directory for its processes and removes it when they end; the
    variable naming it goes too (a process that goes on, such as a test runner, would otherwise
    hand a directory that is gone to every service it starts)."""
    monkeypatch.delenv("PROMETHEUS_MULTIPROC_DIR", raising=False)
    assert CliRunner().invoke(app, ["serve"]).exit_code == 0
    assert "PROMETHEUS_MULTIPROC_DIR" not in os.environ
