"""The command line: simulate, process (no server, resumable), migrate."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from app.cli import app
from app.settings import get_settings

pytestmark = pytest.mark.timeout(300)

runner = CliRunner()


def test_simulate_writes_run_and_truth(tmp_path):
    out = tmp_path / "sim.h5"
    result = runner.invoke(app, ["simulate", str(out), "--length-km", "0.3", "--fs", "5000", "--seed", "4"])
    assert result.exit_code == 0, result.output
    assert out.is_file() and (tmp_path / "sim.truth.h5").is_file()


def test_simulate_on_a_line_of_its_own(tmp_path):
    """--line-id, --track, --vehicle-id, --start-time reach the run's metadata and the reference files."""
    import datetime as dt

    from app.io.runfile import open_run

    out = tmp_path / "docs.h5"
    result = runner.invoke(app, ["simulate", str(out), "--length-km", "0.3", "--fs", "5000", "--seed", "4",
                                 "--no-forces", "--reference", "--line-id", " DOCS ", "--track", "2",
                                 "--vehicle-id", "DOCS-1", "--start-time", "2026-01-15"])
    assert result.exit_code == 0, result.output
    with open_run(out) as run:
        meta = run.metadata
    assert (meta.line_id, meta.track, meta.vehicle_id) == ("DOCS", "2", "DOCS-1")
    assert meta.start_time == dt.datetime(2026, 1, 15, 8, 0, tzinfo=dt.UTC)
    for kind in ("subsidence", "maintenance", "superstructure"):
        ref = pd.read_csv(tmp_path / "docs-reference" / f"{kind}.csv", dtype=str)
        assert set(zip(ref["line_id"], ref["track"], strict=True)) == {("DOCS", "2")}, kind
    result = runner.invoke(app, ["simulate", str(tmp_path / "t.h5"), "--length-km", "0.3", "--fs", "5000",
                                 "--no-forces", "--start-time", "2026-01-15T09:30:00+01:00"])
    assert result.exit_code == 0, result.output
    with open_run(tmp_path / "t.h5") as run:
        assert run.metadata.start_time == dt.datetime(2026, 1, 15, 8, 30, tzinfo=dt.UTC)
        assert (run.metadata.line_id, run.metadata.vehicle_id) == ("SIM", "SIM-1")  # the defaults


@pytest.mark.parametrize(("args", "option", "says"), [
    (["--line-id", "  "], "--line-id", "at least 1 character"),
    (["--track", "x" * 101], "--track", "at most 100 characters"),
    (["--vehicle-id", ""], "--vehicle-id", "at least 1 character"),
    (["--start-time", "2026-13-01"], "--start-time", "not an ISO date"),
    (["--start-time", "2026-01-15T08:00:00"], "--start-time", "UTC offset"),
    (["--start-time", "1899-12-31"], "--start-time", "start time must lie between"),
])
def test_simulate_refuses_bad_metadata_options(tmp_path, args, option, says):
    out = tmp_path / "bad.h5"
    result = runner.invoke(app, ["simulate", str(out), "--length-km", "0.3", *args])
    assert result.exit_code == 2, result.output
    assert option in result.output and says in result.output, result.output
    assert not out.exists()


def test_simulate_with_confounders_and_process_finds_them(tmp_path):
    """--confounders: rough rails with welds and a flat on wheel 11; process reports the flat."""
    from app.simulate.truth import load_truth

    out = tmp_path / "rough.h5"
    result = runner.invoke(app, ["simulate", str(out), "--length-km", "0.4", "--fs", "8000", "--seed", "4",
                                 "--confounders", "--no-forces"])
    assert result.exit_code == 0, result.output
    truth = load_truth(tmp_path / "rough.truth.h5")
    assert truth.line.surface is not None and truth.line.surface.impacts
    assert truth.wheels["11"].flat is not None and truth.wheels["12"].flat is None
    result = runner.invoke(app, ["process", str(out), "--out", str(tmp_path / "o")])
    assert result.exit_code == 0, result.output
    wheels = {w["wheel"]: w for w in json.loads((tmp_path / "o" / "wheels.json").read_text())}
    assert wheels["11"]["flat"] is not None and wheels["12"]["flat"] is None
    assert "track_impact_mm" in pd.read_parquet(tmp_path / "o" / "profiles.parquet").columns


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


def test_help_shows_no_bool_placeholders():
    """`trackvkf --help` and a command's help read as plain options (no "<bool>" for flags)."""
    for args in (["--help"], ["demo", "--help"], ["key", "--help"], ["worker", "--help"]):
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
        assert "<bool>" not in result.output, result.output
        assert "--help" in result.output and "Show this message and exit." in result.output


@pytest.mark.parametrize("command", [["key", "list"], ["user", "list"], ["serve"], ["worker", "--once"]])
def test_commands_outside_the_project_give_a_hint_and_create_nothing(tmp_path, monkeypatch, command):
    """From another directory the default relative SQLite URL names no database: one line of
    advice and exit status 2, no traceback, no ./var created."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("TRACKVKF_DATABASE_URL", raising=False)
    get_settings.cache_clear()
    try:
        result = runner.invoke(app, command)
    finally:
        get_settings.cache_clear()
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    out = result.output.strip()
    assert out.startswith("error: no database at ") and "trackvkf migrate" in out, out
    assert str(tmp_path) in out
    assert len(out.splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_unmigrated_database_asks_for_migrate(tmp_path, monkeypatch):
    import sqlite3

    path = tmp_path / "empty.db"
    sqlite3.connect(path).close()
    monkeypatch.setenv("TRACKVKF_DATABASE_URL", f"sqlite:///{path}")
    get_settings.cache_clear()
    try:
        result = runner.invoke(app, ["key", "list"])
    finally:
        get_settings.cache_clear()
    assert result.exit_code == 2, result.output
    assert "is not migrated: run `trackvkf migrate` first" in result.output


def test_key_revoke_by_name(tmp_path, monkeypatch):
    """``key revoke --name N`` revokes every active key named N and only those; neither id nor name,
    both, or a name without an active key: exit 2, nothing revoked."""
    from app.db import migrate

    url = f"sqlite:///{tmp_path / 'keys.db'}"
    migrate.upgrade(url)
    monkeypatch.setenv("TRACKVKF_DATABASE_URL", url)
    get_settings.cache_clear()
    try:
        for name in ("recorder 3", "recorder 3", "loader"):
            assert runner.invoke(app, ["key", "create", name]).exit_code == 0
        for args in (["key", "revoke"], ["key", "revoke", "3", "--name", "loader"],
                     ["key", "revoke", "--name", "nobody"]):
            result = runner.invoke(app, args)
            assert result.exit_code == 2, (args, result.output)
        result = runner.invoke(app, ["key", "revoke", "--name", "recorder 3"])
        assert result.exit_code == 0, result.output
        assert "API key 1 revoked" in result.output and "API key 2 revoked" in result.output
        states = {line.split("\t")[0]: line.split("\t")[-1]
                  for line in runner.invoke(app, ["key", "list"]).output.splitlines() if "\t" in line}
        assert states["1"].startswith("revoked") and states["2"].startswith("revoked") and states["3"] == "active"
        assert runner.invoke(app, ["key", "revoke", "--name", "recorder 3"]).exit_code == 2  # none active now
    finally:
        get_settings.cache_clear()


def test_engine_warnings_are_one_line_each_and_kept_in_meta():
    """Warnings inside the block reach the writer once per distinct message, without a source
    line, and are counted."""
    import warnings

    from app.analysis.vkf import VKFWarning
    from app.cli._warnings import engine_warnings

    lines: list[str] = []
    with engine_warnings(lines.append) as seen:
        for _ in range(3):
            warnings.warn("orders [(1, 2)] come closer than their bandwidth", VKFWarning, stacklevel=1)
        warnings.warn("other", UserWarning, stacklevel=1)
    assert lines[0] == "warning: VKFWarning: orders [(1, 2)] come closer than their bandwidth"
    assert lines[1] == "warning: UserWarning: other"
    assert lines[2].startswith("warning: VKFWarning repeated 3 times")
    assert not any("warnings.warn" in line or ".py:" in line for line in lines)
    assert seen.as_list()[0] == {"category": "VKFWarning", "message": "orders [(1, 2)] come closer than their bandwidth", "count": 3}
