"""Analytics endpoints on three simulated, processed runs and the simulator's reference data,
checked against the simulator's ground truth."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tests.analytics.conftest import KM_ERROR_M, LINE_ID, TRACK
from tests.analytics.support import import_reference, store_run
from tests.api.support import auth_headers, create_api_key, make_settings


@pytest.fixture(scope="module")
def api(sim_set, tmp_path_factory):
    """(client, {name: run_id}) with runs A, B, C stored and the reference data imported."""
    from app.db import migrate
    from app.main import create_app

    settings = make_settings(tmp_path_factory.mktemp("analytics-api"))
    migrate.upgrade(settings.database_url)
    headers = auth_headers(create_api_key(settings.database_url))
    with TestClient(create_app(settings), headers=headers) as client:
        client.settings = settings  # type: ignore[attr-defined]
        ids = {name: store_run(client, run) for name, run in sim_set.runs.items()}
        import_reference(client, sim_set.reference.files)
        yield client, ids


def _get(client, path, **params):
    r = client.get(f"/api/v1{path}", params=params)
    assert r.status_code == 200, r.text
    return r.json()


@pytest.mark.parametrize("name", ["A", "C"])
def test_subsidence_fit_recovers_truth_per_wheel(api, sim_set, name):
    client, ids = api
    # 16 intervals per run are checked: 99 % keeps the family-wise error small
    body = _get(client, "/analytics/subsidence-fit", line_id=LINE_ID, track=TRACK, run_ids=str(ids[name]),
                confidence=0.99)
    assert body["log_base"] == "e" and body["amplitude_unit"] == "m/s^2" and body["subsidence_unit"] == "mm"
    run = sim_set.runs[name]
    a, b = sim_set.reference.subsidence_fit_at(run.speed_kmh / 3.6, run.truth.alpha, run.truth.v_ref_mps)
    assert [w["wheel"] for w in body["wheels"]] == ["11", "12", "41", "42"]
    for w in body["wheels"]:
        assert w["slope_ci"][0] <= a <= w["slope_ci"][1], (w["wheel"], w["slope_ci"], a)
        assert w["intercept_ci"][0] <= b <= w["intercept_ci"][1], (w["wheel"], w["intercept_ci"], b)
        assert w["slope_ci"][1] - w["slope_ci"][0] < 0.2 * a  # informative, not vacuous
        assert w["n_samples"] > 5000 and 0 < len(w["points"]["amplitude"]) <= 5000
        assert w["rmse"] < 2 * sim_set.reference.subsidence_noise_mm


def test_subsidence_fit_on_speed_normalised_amplitude_pools_speeds(api, sim_set):
    client, ids = api
    params = {"line_id": LINE_ID, "track": TRACK, "run_ids": f"{ids['A']},{ids['C']}", "confidence": 0.99}
    raw = _get(client, "/analytics/subsidence-fit", **params)
    body = _get(client, "/analytics/subsidence-fit", normalise="true", reference_speed_kmh=100, **params)
    a, b = sim_set.reference.subsidence_slope_mm, sim_set.reference.subsidence_intercept_mm
    for w, r in zip(body["wheels"], raw["wheels"], strict=True):
        # the estimated speed exponent adds its own (small) error: fixed tolerances here
        assert abs(w["slope"] - a) < 0.02 and abs(w["intercept"] - b) < 0.01, (w["slope"], w["intercept"])
        assert w["rmse"] < 0.8 * r["rmse"]  # mixing speeds blurs the raw fit


def test_unsprung_mass_within_5_percent(api, sim_set):
    client, ids = api
    body = _get(client, "/analytics/unsprung-mass", line_id=LINE_ID, track=TRACK)
    assert sorted(body["run_ids"]) == sorted(ids.values())
    mass = sim_set.runs["A"].truth.unsprung_mass_kg
    for w in body["wheels"]:
        assert abs(w["mass_kg"] - mass) < 0.05 * mass, w["mass_kg"]
        assert w["plausible"] and w["r2"] > 0.9
    bad = _get(client, "/analytics/unsprung-mass", line_id=LINE_ID, mass_min_kg=400, mass_max_kg=600)
    assert not any(w["plausible"] for w in bad["wheels"])


def test_predicted_subsidence_follows_measurement(api, sim_set):
    client, ids = api
    body = _get(client, f"/runs/{ids['A']}/predicted-subsidence", wheel="12", km_from=12.2, km_to=13.3,
                fit_run_ids=str(ids["A"]))
    pred, meas = np.array(body["subsidence_mm"], float), np.array(body["measured_mm"], float)
    assert len(pred) > 3000 and body["log_base"] == "e"
    ok = np.isfinite(pred) & np.isfinite(meas)
    assert ok.mean() > 0.95
    assert np.sqrt(np.mean((pred[ok] - meas[ok]) ** 2)) < 2 * sim_set.reference.subsidence_noise_mm


def test_maintenance_correlation(api, sim_set):
    client, ids = api
    body = _get(client, "/analytics/maintenance", line_id=LINE_ID, track=TRACK, run_ids=str(ids["A"]),
                type="tamping,grinding", since="2010-01-01")
    reg = body["regression"]
    assert reg["n"] > 5000 and reg["slope"] > 0 and reg["p_value"] < 0.01
    assert sum(g["n_bins"] for g in body["groups"]) == reg["n"]
    for g in body["groups"]:
        assert g["whisker_low"] <= g["q1"] <= g["median"] <= g["q3"] <= g["whisker_high"]
    # the counts behind the groups: compare with an independent count from the file
    import pandas as pd

    acts = pd.read_csv(sim_set.reference.files["maintenance"])
    acts = acts[acts["type"].isin(["tamping", "grinding"]) & (acts["date"] >= "2010-01-01")]
    x = 12_600.125
    n = int(((acts.km_from * 1000 <= x) & (acts.km_to * 1000 >= x)).sum())
    assert n in [g["n_actions"] for g in body["groups"]]
    with pytest.raises(AssertionError):
        _get(client, "/analytics/maintenance", line_id=LINE_ID, type="polishing")


def test_superstructure_clusters_and_flagged_anomalies(api, sim_set):
    client, ids = api
    body = _get(client, "/analytics/superstructure", line_id=LINE_ID, track=TRACK)
    assert body["normalised"]
    types = {t["type"]: t for t in body["types"]}
    assert set(types) == {s.type for s in sim_set.line.sections}
    amp = sim_set.line.amplitude_vref
    if "slab" in types and "b91_pads" in types:
        assert types["slab"]["median"] > 2 * types["b91_pads"]["median"]
        assert abs(types["b91_pads"]["median"] / amp["b91_pads"] - 1) < 0.15
    flagged = body["flagged"]
    assert flagged, "the soft and hard spots must be flagged"
    anomalies = [(a.track_from_m, a.track_to_m) for a in sim_set.line.anomalies]
    for f in flagged:  # every flag lies on an anomaly
        mid = 500 * (f["km_from"] + f["km_to"])
        assert any(lo - 60 <= mid <= hi + 60 for lo, hi in anomalies), f
    for lo, hi in anomalies:  # every anomaly is flagged
        assert any(lo <= 500 * (f["km_from"] + f["km_to"]) <= hi for f in flagged)


def test_speed_exponent_and_normalised_profile(api, sim_set):
    client, ids = api
    runs = f"{ids['A']},{ids['C']}"
    body = _get(client, "/analytics/speed-normalisation", line_id=LINE_ID, track=TRACK, run_ids=runs)
    alpha = sim_set.runs["A"].truth.alpha
    fits = {t["type"]: t for t in body["types"]}
    assert fits["*"]["method"] == "within"
    for t in fits.values():
        if t["n_samples"] > 2000:
            assert t["exponent_ci"][0] <= alpha <= t["exponent_ci"][1], t
            assert t["plausible"] is True and t["warning"] is None, t
    prof = _get(client, f"/runs/{ids['C']}/speed-normalised-profile", wheel="11", fit_run_ids=runs)
    norm = np.array(prof["amplitude_normalised"], float)
    km = np.array(prof["km"])
    tb = sim_set.runs["C"].truth.bins["11"]
    truth_ref = np.interp(km * 1000, tb.track_m, tb.amplitude_vref_mps2)
    ok = np.isfinite(norm)
    assert ok.mean() > 0.9
    assert abs(np.median(norm[ok] / truth_ref[ok]) - 1) < 0.05


def test_alignment_recovers_imposed_shift(api):
    client, ids = api
    body = _get(client, f"/runs/{ids['B']}/alignment", reference_run_id=ids["A"])
    assert abs(body["shift_m"] + KM_ERROR_M) < 1.0, body["shift_m"]
    assert body["shift_confidence"] > 0.2
    same = _get(client, f"/runs/{ids['A']}/alignment")
    assert same["reference_run_id"] == ids["A"] and same["shift_m"] == 0.0
    # the same quantity answers the same everywhere: the reference run aligned to itself
    seg = _get(client, "/analytics/segments", line_id=LINE_ID, track=TRACK, run_ids=f"{ids['A']},{ids['B']}")
    ref = next(r for r in seg["runs"] if r["run_id"] == ids["A"])
    assert same["shift_confidence"] == ref["shift_confidence"] == 1.0
    other = next(r for r in seg["runs"] if r["run_id"] == ids["B"])
    assert other["shift_confidence"] == pytest.approx(body["shift_confidence"])


def test_segments_aligned_repeatability(api):
    client, ids = api
    runs = f"{ids['A']},{ids['B']}"
    aligned = _get(client, "/analytics/segments", line_id=LINE_ID, track=TRACK, run_ids=runs)
    raw = _get(client, "/analytics/segments", line_id=LINE_ID, track=TRACK, run_ids=runs, align="false")
    assert [r["run_id"] for r in aligned["runs"]] == [ids["A"], ids["B"]]
    assert abs(aligned["runs"][1]["shift_m"] + KM_ERROR_M) < 1.0
    m = np.array(aligned["matrix"], float)
    assert m.shape == (2, len(aligned["km"]))
    # same speed, same track: alignment shrinks the run-to-run spread
    sa, sr = np.array(aligned["spread"], float), np.array(raw["spread"], float)
    assert np.nanmean(sa) < 0.8 * np.nanmean(sr)
    trend = _get(client, "/analytics/segment-trend", line_id=LINE_ID, track=TRACK, km=12.95, run_ids=runs)
    assert [p["run_id"] for p in trend["points"]] == [ids["A"], ids["B"]]
    assert all(p["amplitude"] is not None and p["amplitude"] > 0 for p in trend["points"])


def test_no_reference_data_gives_empty_results(make_client, sim_set):
    client = make_client()
    run_id = store_run(client, sim_set.runs["A"])
    sub = _get(client, "/analytics/subsidence-fit", line_id=LINE_ID)
    assert all(w["n_samples"] == 0 and w["slope"] is None for w in sub["wheels"])
    main = _get(client, "/analytics/maintenance", line_id=LINE_ID)
    assert main["groups"] == [] and main["regression"]["n"] == 0
    sup = _get(client, "/analytics/superstructure", line_id=LINE_ID)
    assert sup["types"] == [] and sup["flagged"] == []
    pred = _get(client, f"/runs/{run_id}/predicted-subsidence", wheel="12")
    assert pred["model"] is None
    assert client.get("/api/v1/analytics/subsidence-fit").status_code == 422
    r = client.get("/api/v1/analytics/subsidence-fit", params={"run_ids": "1,x"})
    assert r.status_code == 422 and r.json()["field"] == "run_ids"
    assert client.get("/api/v1/analytics/subsidence-fit", params={"run_ids": "999"}).status_code == 404
