"""The command line with recorder files: simulate --recorder, process --channel-map --geometry."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from app.cli import app

pytestmark = pytest.mark.timeout(300)

runner = CliRunner()


def test_simulate_recorder_and_process_with_channel_map_and_geometry(tmp_path):
    out = tmp_path / "sim.mf4"
    result = runner.invoke(app, ["simulate", str(out), "--length-km", "1.2", "--fs", "4000", "--seed", "2",
                                 "--recorder", "mdf4", "--gnss", "--no-forces"])
    assert result.exit_code == 0, result.output
    cmap, meta, geo = (tmp_path / f"sim.{s}" for s in ("channel-map.json", "metadata.json", "line.geojson"))
    assert cmap.is_file() and meta.is_file() and geo.is_file()
    result = runner.invoke(app, ["process", str(out), "--out", str(tmp_path / "o"), "--metadata", str(meta)])
    assert result.exit_code == 2 and "channel_map" in result.output
    result = runner.invoke(app, ["process", str(out), "--out", str(tmp_path / "o"), "--metadata", str(meta),
                                 "--channel-map", str(cmap)])
    assert result.exit_code == 2 and "lat: GNSS positions need the line geometry" in result.output
    result = runner.invoke(app, ["process", str(out), "--out", str(tmp_path / "o"), "--metadata", str(meta),
                                 "--channel-map", str(cmap), "--geometry", str(geo)])
    assert result.exit_code == 0, result.output
    profiles = pd.read_parquet(tmp_path / "o" / "profiles.parquet")
    truth_km0 = json.loads(meta.read_text())
    assert "km_start" not in truth_km0  # placed by GNSS, not by the metadata
    km = profiles.loc[profiles["wheel"] == "11", "km"]
    assert 11.99 < km.min() < 12.05 and 13.1 < km.max() < 13.25  # simulate_run starts at km 12
