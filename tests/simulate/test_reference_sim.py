"""Simulated reference data: the files follow the stated relations; odometry error in the metadata."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from app.analysis.stiffness.maintenance import count_actions
from app.simulate.reference import simulate_reference
from app.simulate.track import generate_line


@pytest.fixture(scope="module")
def line():
    return generate_line(0.0, 20_000.0, np.random.default_rng(3), n_anomalies=4)


def test_subsidence_follows_log_amplitude_per_rail(line, tmp_path):
    ref = simulate_reference(line, tmp_path, seed=2, subsidence_noise_mm=0.0)
    sub = pd.read_csv(ref.files["subsidence"])
    assert list(sub.columns) == ["line_id", "track", "km", "rail", "subsidence_mm", "date"]
    for rail in (1, 2):
        s = sub[sub.rail == rail]
        z = line.amplitude_at_vref(s.km.to_numpy() * 1000, rail)
        np.testing.assert_allclose(s.subsidence_mm, 0.30 * np.log(z) - 1.65, atol=1e-6)
    assert json.loads(Path(ref.files["truth"]).read_text())["subsidence_slope_mm"] == 0.30


def test_maintenance_counts_match_expectation(line, tmp_path):
    ref = simulate_reference(line, tmp_path, seed=5, fmt="parquet")
    acts = pd.read_parquet(ref.files["maintenance"])
    assert set(acts["type"]) <= {"tamping", "grinding", "rail_replacement", "ballast_cleaning", "other"}
    assert (acts.km_to > acts.km_from).all()
    x = line.centres()[::200]  # one position per 50 m block
    observed = count_actions(x, acts.km_from.to_numpy() * 1000, acts.km_to.to_numpy() * 1000)
    expected = ref.expected_actions(x)
    assert observed.sum() == pytest.approx(expected.sum(), rel=0.1)
    # stiff track is maintained more: observed counts follow the expected rate
    assert np.corrcoef(observed, expected)[0, 1] > 0.5
    since = ref.expected_actions(x, kinds=("tamping",), since_year=2015)
    t = acts[(acts["type"] == "tamping") & (acts["date"] >= "2015-01-01")]
    obs = count_actions(x, t.km_from.to_numpy() * 1000, t.km_to.to_numpy() * 1000)
    assert obs.sum() == pytest.approx(since.sum(), rel=0.2)


def test_superstructure_file_is_the_section_table(line, tmp_path):
    ref = simulate_reference(line, tmp_path)
    sup = pd.read_csv(ref.files["superstructure"])
    assert list(sup["type"]) == [s.type for s in line.sections]
    np.testing.assert_allclose(sup.km_from, [s.km_from for s in line.sections])


def test_odometry_error_in_metadata(tmp_path):
    from app.io import open_run
    from app.simulate.run import simulate_run
    from app.simulate.truth import load_truth

    truth = simulate_run(tmp_path / "r.h5", length_km=0.2, fs=2000.0, seed=1, km_error_m=7.5)
    with open_run(tmp_path / "r.h5") as run:
        assert run.metadata.km_start == pytest.approx(12.0075)
    assert truth.km_start == 12.0 and load_truth(truth.truth_path).km_error_m == 7.5
