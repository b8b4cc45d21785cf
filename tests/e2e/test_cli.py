"""The command line: simulate, process (no server, resumable), migrate."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from app.cli import app
from app.core.config import get_settings

pytestmark = pytest.mark.timeout(300)

runner = CliRunner()


def test_simulate_writes_run_and_truth(tmp_path):
    out = tmp_path / "sim.h5"
    result = runner.invoke(app, ["simulate", str(out), "--length-km", "0.3", "--fs", "5000", "--seed", "4"])
    assert result.exit_code == 0, result.output
    assert out.is_file() and (tmp_path / "sim.truth.h5").is_file()


def test_process_writes_profiles_and_wheels_and_resumes(tmp_path, short_sim_run):
    path, truth = short_sim_run
    out = tmp_path / "out"
    result = runner.invoke(app, ["process", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    profiles = pd.read_parquet(out / "profiles.parquet")
    assert set(profiles["wheel"]) == set(truth.wheels)
    assert len(pd.read_csv(out / "profiles.csv")) == len(profiles)
    orders = pd.read_csv(out / "wheel_orders.csv", dtype={"wheel": str})
    assert len(orders) == 4 * 11
    wheel_profiles = pd.read_parquet(out / "wheel_profiles.parquet")
    assert len(wheel_profiles) == 4 * 360
    meta = json.loads((out / "meta.json").read_text())
    assert meta["settings"]["n_wheel_orders"] == 11 and len(meta["source_sha256"]) == 64

    # a second call reuses the validated file and the chunk results
    chunks = sorted((out / ".work").rglob("chunk-*.npz"))
    stamps = [p.stat().st_mtime_ns for p in chunks]
    result = runner.invoke(app, ["process", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert [p.stat().st_mtime_ns for p in chunks] == stamps
    pd.testing.assert_frame_equal(pd.read_parquet(out / "profiles.parquet"), profiles)


def test_process_rejects_bad_input(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("Z11,speed\n1,2\n")
    result = runner.invoke(app, ["process", str(bad), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    result = runner.invoke(app, ["process", str(bad), "--filter-order", "9"])
    assert result.exit_code != 0 and "filter_order" in result.output


def test_migrate_command(tmp_path, monkeypatch):
    url = f"sqlite:///{tmp_path / 'cli.sqlite'}"
    monkeypatch.setenv("TRACKVKF_DATABASE_URL", url)
    get_settings.cache_clear()
    try:
        result = runner.invoke(app, ["migrate"])
    finally:
        get_settings.cache_clear()
    assert result.exit_code == 0, result.output
    from alembic.script import ScriptDirectory

    from app.db import migrate

    head = ScriptDirectory.from_config(migrate.alembic_config(url)).get_current_head()
    assert result.output.strip().endswith(f"at {head}")
