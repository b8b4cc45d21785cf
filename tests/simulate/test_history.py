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


def test_the_real_line_holds_every_confounder_with_its_truth():
    from app.simulate.history import REAL_LINE_SPEEDS_MPS, real_line_history

    spec = real_line_history(seed=0)
    x0, x1 = 12_000.0, 15_000.0
    # four superstructure classes, the ramps at both ends
    assert [s.type for s in spec.line.sections] == ["slab", "b91_no_pads", "timber", "b91_pads"]
    assert spec.ramps() == (x0 + 500.0, x1 - 400.0)
    # rough rails, welds every 60–120 m (each rail its own dip), two joints: only the joints in the register
    surf = spec.line.surface
    assert surf is not None and surf.spectrum is not None
    feats = spec.rail_features()
    welds = [f for f in feats if f.kind == "weld"]
    joints = [f for f in feats if f.kind == "joint"]
    assert 28 <= len(welds) <= 40 and len(joints) == 2
    gaps = np.diff([f.track_m for f in welds])
    assert gaps.min() >= 60.0 - 1e-9 and gaps.max() <= 120.0 + 1e-9
    depths = np.array([d for f in welds for d in f.depth_m.values()])
    assert depths.min() >= 0.2e-3 and depths.max() <= 0.4e-3 and len(depths) == 2 * len(welds)
    assert all(f.in_register for f in joints) and not any(f.in_register for f in welds)
    assert list(spec.asset_register()["type"]) == ["insulated_joint"] * 2
    # two speed groups, two of each in every four runs; every third run by the second vehicle
    runs = spec.runs
    assert len(runs) == 24 and runs[-1].day == pytest.approx(345.0)
    v = np.array([r.cruise_kmh for r in runs]) / 3.6
    group = np.abs(v[:, None] - np.array(REAL_LINE_SPEEDS_MPS)[None, :]).argmin(axis=1)
    assert np.all(np.abs(v / np.array(REAL_LINE_SPEEDS_MPS)[group] - 1) <= 0.03 + 1e-9)
    assert all(group[i:i + 4].sum() == 2 for i in range(0, 24, 4))
    assert runs[0].vehicle == 0 and runs[0].km_error_m == 0.0
    assert 7 <= sum(r.vehicle for r in runs) <= 8
    v2 = spec.vehicle_of(next(r for r in runs if r.vehicle == 1))
    assert (v2.wheel_diameter_m, v2.unsprung_mass_factor, v2.sensor_gain) == (0.86, 1.25, 1.15)
    # maintenance: the tamping and the grinding recorded, the grinding in the rails' surface
    m = spec.maintenance()
    assert list(m["type"]) == ["tamping", "grinding"]
    assert m.iloc[1]["km_to"] - m.iloc[1]["km_from"] == pytest.approx(0.5)
    (gday,) = spec.grinding_days()
    assert sum(r.day > gday for r in runs) == 9
    # the support truth of the newest run: the soft spot, the tamping, the developing place, the new step
    truth = {t.kind: t for t in spec.truth_places(runs[-1].day)}
    assert set(truth) == {"anomaly", "tamping", "developing", "change"}
    assert truth["anomaly"].log_change == pytest.approx(np.log(0.6))
    assert truth["change"].log_change == pytest.approx(np.log(0.8))
    assert runs[-2].day < truth["change"].since_day < runs[-1].day
    assert sum(r.day > truth["developing"].since_day for r in runs) == 10
    assert np.expm1(truth["developing"].log_change) == pytest.approx(-0.35, abs=0.01)
    # the fingerprint names the rails, the vehicles and the register; the history is the same from its seed
    assert spec.fingerprint() == real_line_history(seed=0).fingerprint() != real_line_history(seed=1).fingerprint()
    short = real_line_history(seed=0, length_km=1.2, n_runs=6)
    assert {t.kind for t in short.truth_places(short.runs[-1].day)} == {"anomaly", "tamping", "developing", "change"}
    with pytest.raises(ValueError, match="length_km"):
        real_line_history(length_km=1.0)
    with pytest.raises(ValueError, match="n_runs"):
        real_line_history(n_runs=5)


def test_a_vehicle_brings_its_own_wheels_mass_and_sensor_gain():
    from app.simulate.amplitude import ResonanceResponse
    from app.simulate.history import HistoryVehicle

    plain = HistoryVehicle("A", 1)
    assert plain.simulation_options() == {"vehicle_id": "A"}
    assert plain.diameters()["11"] == pytest.approx(0.92)
    heavy = HistoryVehicle("B", 2, wheel_diameter_m=0.86, unsprung_mass_factor=1.25, sensor_gain=1.15)
    opts = heavy.simulation_options()
    assert set(heavy.diameters().values()) == {0.86}
    assert opts["sensor_gain"] == 1.15 and opts["unsprung_mass_kg"] == pytest.approx(375.0)
    resp = opts["amplitude_model"]
    assert isinstance(resp, ResonanceResponse) and resp.track.wheel_mass == pytest.approx(1.25 * 592.0)
    # the line's amplitudes are the reference vehicle's: the heavier wheel answers with its own resonance
    ratio = resp.factor(np.array([1]), np.array([resp.v_ref_mps]))[0]
    assert ratio != pytest.approx(1.0, abs=0.02)
    assert ResonanceResponse(reference_track=ResonanceResponse().track).factor(
        np.array([1]), np.array([40.0])) == pytest.approx(ResonanceResponse().factor(np.array([1]), np.array([40.0])))
    with pytest.raises(ValueError, match="sensor_gain"):
        HistoryVehicle("C", 3, sensor_gain=0.0)
    with pytest.raises(ValueError, match="wheel_diameter_m"):
        HistoryVehicle("C", 3, wheel_diameter_m=2.0)
    spec = _spec([])
    with pytest.raises(ValueError, match="vehicle"):
        dataclasses.replace(spec, runs=(HistoryRun(0.0, 100.0, vehicle=1),))
