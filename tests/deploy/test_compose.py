"""docker-compose.yml validated offline against the Compose specification
(check-jsonschema's vendored compose-spec schema; no Docker engine needed), plus
the properties the production mode relies on."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
COMPOSE = ROOT / "docker-compose.yml"


def _check_jsonschema() -> str:
    exe = Path(sys.executable).with_name("check-jsonschema")
    found = str(exe) if exe.is_file() else shutil.which("check-jsonschema")
    if found is None:
        pytest.fail("check-jsonschema is not installed (pip install check-jsonschema)")
    return found


def _validate(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [_check_jsonschema(), "--builtin-schema", "vendor.compose-spec", str(path)],
        capture_output=True, text=True, timeout=120,
    )


def test_compose_file_matches_the_compose_specification():
    proc = _validate(COMPOSE)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_validation_rejects_a_broken_compose_file(tmp_path):
    doc = yaml.safe_load(COMPOSE.read_text())
    doc["services"]["worker"]["healthcheck"]["interval"] = 10  # must be a duration string
    doc["services"]["api"]["depends_on"]["db"]["condition"] = "service_ready"  # no such condition
    broken = tmp_path / "docker-compose.yml"
    broken.write_text(yaml.safe_dump(doc))
    proc = _validate(broken)
    assert proc.returncode != 0, proc.stdout


def test_compose_services_of_the_production_mode():
    doc = yaml.safe_load(COMPOSE.read_text())
    services = doc["services"]
    assert set(services) == {"db", "migrate", "api", "worker"}
    for name in ("db", "api", "worker"):
        assert "test" in services[name]["healthcheck"], name
    # migrations run once, before the API and the workers start
    assert services["migrate"]["restart"] == "no"
    assert services["migrate"]["command"] == ["trackvkf", "migrate"]
    for name in ("api", "worker"):
        deps = services[name]["depends_on"]
        assert deps["migrate"]["condition"] == "service_completed_successfully"
        assert deps["db"]["condition"] == "service_healthy"
        assert services[name]["environment"]["TRACKVKF_DATABASE_URL"].startswith("postgresql+psycopg://")
        assert "runs:/data/runs" in services[name]["volumes"]
    # workers scale with --scale worker=N: no fixed name, no host port
    worker = services["worker"]
    assert "container_name" not in worker and "ports" not in worker
    assert worker["command"][:2] == ["trackvkf", "worker"]
    assert {"pgdata", "runs"} <= set(doc["volumes"])
    assert "pgdata:/var/lib/postgresql/data" in services["db"]["volumes"]
