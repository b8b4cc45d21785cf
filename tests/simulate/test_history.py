"""The history simulator: the track changing over time, the runs' speed ramps, the truth it reports,
and its files (runs whose truth shows the track of their day, reference CSVs, reuse)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from app.simulate.history import (
    HistoryRun,
    HistorySpec,
    TrackChange,
    planted_history,
    ramp_profile,
    uniform_history,
    write_history,
)
from app.simulate.track import TrackSection, generate_line


def test_ramp_profile_reaches_the_speeds_at_the_given_distances():
    prof = ramp_profile(2400.0, 65.0, 120.0, 60.0, 500.0, 400.0)
    t = prof.time_at_distance(np.array([0.0, 500.0, 2000.0, 2400.0]))
    v = prof.speed(t) * 3.6
    assert v == pytest.approx([65.0, 120.0, 120.0, 60.0], abs=0.01)
    with pytest.raises(ValueError, match="ramp_in_m"):
        ramp_profile(800.0, 65.0, 120.0, 60.0, 500.0, 400.0)
    with pytest.raises(ValueError, match="cruise_kmh"):
        ramp_profile(2400.0, 65.0, 0.0, 60.0, 500.0, 400.0)


def _spec(changes) -> HistorySpec:
    line = generate_line(11_800.0, 14_600.0, seed=1, sections=(TrackSection(11_800.0, 14_600.0, "slab"),),
                         anomalies=())
    return HistorySpec(line=line, runs=(HistoryRun(0.0, 100.0),), changes=tuple(changes))


def test_changes_developing_places_and_a_tamping_that_repairs_them():
    change = TrackChange("change", 12_100.0, 12_120.0, 10.0, 0.8, taper_m=0.0)
    dev = TrackChange("developing", 13_000.0, 13_040.0, 0.0, rate_per_year=0.73, taper_m=0.0)
    tamp = TrackChange("tamping", 12_950.0, 13_100.0, 100.0, 0.85, rate_per_year=0.1, taper_m=0.0)
    spec = _spec([change, dev, tamp])
    x = np.array([12_110.0, 13_020.0, 13_080.0, 13_500.0])
    assert spec.log_factor(5.0, x) == pytest.approx([0.0, 0.01, 0.0, 0.0], abs=1e-3)
    assert spec.log_factor(50.0, x) == pytest.approx([np.log(0.8), 0.1, 0.0, 0.0], abs=1e-3)
    # the tamping removed the developing place and applies its own factor, which then regrows
    after = spec.log_factor(100.0, x)
    assert after == pytest.approx([np.log(0.8), np.log(0.85), np.log(0.85), 0.0], abs=1e-3)
    assert spec.log_factor(100.0 + 365.25, x)[1] == pytest.approx(np.log(0.85) + 0.1, abs=1e-3)
    # the line of a day carries it, both rails
    day = spec.line_at(50.0)
    i = int(np.argmin(np.abs(spec.line.centres() - 12_110.0)))
    assert day.factor[:, i] == pytest.approx(spec.line.factor[:, i] * 0.8)
    # truth: the change, the developing place until repaired, the tamping with its effect
    kinds = {t.kind: t for t in spec.truth_places(50.0)}
    assert set(kinds) == {"change", "developing"}
    assert kinds["change"].log_change == pytest.approx(np.log(0.8))
    later = {t.kind: t for t in spec.truth_places(120.0)}
    assert set(later) == {"change", "tamping"}
    assert later["tamping"].log_change == pytest.approx(np.log(0.85), abs=1e-6)
    assert spec.maintenance().to_dict("records") == [
        {"line_id": "HIST", "track": "1", "km_from": 12.95, "km_to": 13.1, "type": "tamping", "date": "2025-04-16"}]


def test_track_change_checks_arguments():
    with pytest.raises(ValueError, match="kind"):
        TrackChange("grinding", 0.0, 1.0, 0.0)
    with pytest.raises(ValueError, match="factor"):
        TrackChange("change", 0.0, 1.0, 0.0, factor=0.0)
    with pytest.raises(ValueError, match="track_from_m"):
        TrackChange("change", 2.0, 1.0, 0.0)


def test_scenarios_spread_cruise_speeds_and_keep_the_reference_run_exact():
    spec = planted_history(n_runs=12)
    cruise = np.array([r.cruise_kmh for r in spec.runs])
    assert cruise.min() == pytest.approx(108.0) and cruise.max() == pytest.approx(132.0)
    assert spec.runs[0].km_error_m == 0.0 and np.std([r.km_error_m for r in spec.runs[1:]]) > 2.0
    kinds = sorted(c.kind for c in spec.changes)
    assert kinds == ["change", "change", "developing", "tamping"]
    assert {s.type for s in spec.line.sections} == {"slab", "b91_no_pads", "b91_pads"}
    uni = uniform_history(n_runs=3)
    assert len(uni.line.sections) == 1 and uni.changes == () and uni.line.anomalies == ()
    with pytest.raises(ValueError, match="superstructure"):
        uniform_history(superstructure="wood")


def test_write_history_writes_runs_of_their_day_and_reuses_them(tmp_path):
    from app.simulate.truth import load_truth, truth_path_for

    spec = planted_history(n_runs=12, length_km=2.0)
    late = spec.runs[-1]
    short = dataclasses.replace(spec, runs=(spec.runs[0], late), length_km=2.0, fs=2000.0)
    files = write_history(short, tmp_path)
    assert len(files.runs) == 2 and len(files.written) == 4
    sup = pd.read_csv(files.superstructure)
    assert list(sup["type"]) == ["slab", "b91_no_pads", "b91_pads"]
    assert len(pd.read_csv(files.maintenance)) == 1
    change = next(c for c in spec.changes if c.kind == "change" and c.factor < 1)
    first, last = (load_truth(truth_path_for(p)) for p in files.runs)
    w0, w1 = first.bins["11"], last.bins["11"]
    x = 0.5 * (change.track_from_m + change.track_to_m)
    f0 = w0.stiffness_factor[np.argmin(np.abs(w0.track_m - x))]
    f1 = w1.stiffness_factor[np.argmin(np.abs(w1.track_m - x))]
    assert f1 / f0 == pytest.approx(0.8, rel=1e-6)
    again = write_history(short, tmp_path)
    assert again.written == [] and again.runs == files.runs


def test_demo_history_on_the_demo_line():
    from app.simulate.history import demo_history

    line = generate_line(11_850.0, 15_150.0, seed=3)
    spec = demo_history(line, km_start=12.0, length_km=3.0)
    assert len(spec.runs) == 10 and spec.line_id == "SIM"
    kinds = sorted(c.kind for c in spec.changes)
    assert kinds == ["change", "developing", "developing", "tamping"]
    tamping = next(c for c in spec.changes if c.kind == "tamping")
    assert spec.runs[0].day < tamping.day < spec.runs[-1].day
    assert len(spec.maintenance()) == 1
    with pytest.raises(ValueError, match="length_km"):
        demo_history(line, km_start=12.0, length_km=1.0)
