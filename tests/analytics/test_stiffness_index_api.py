"""Reference curves and the stiffness index over the API (runs A, B at 100 km/h and C at 140 km/h)."""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pytest

from tests.analytics.conftest import LINE_ID, TRACK
from tests.analytics.support import get, store_run


def _profile(client, run_id, **params):
    return get(client, f"/runs/{run_id}/profile", index="true", **params)


def test_reference_curves_are_cached_per_line_and_cover_both_speeds(api, sim_set):
    client, ids = api
    body = get(client, "/analytics/reference-curves", line_id=LINE_ID, track=TRACK)
    assert sorted(body["run_ids"]) == sorted(ids.values())
    types = {s.type for s in sim_set.line.sections}
    assert {c["class"] for c in body["classes"]} <= types | {""}
    for c in body["classes"]:
        if c["n_samples"] < 200:
            continue
        assert c["method"] == "within"  # every location was passed at 100 and at 140 km/h
        lo, hi = c["speed_range_kmh"]
        assert lo < 101 and hi > 139, c["speed_range_kmh"]
        amp = np.array(c["amplitude"], float)
        v = np.array(c["speed_kmh"], float)
        # the power-law option of the simulator: A_ref(140) / A_ref(100) = 1.4 ** 1.5
        a100, a140 = np.interp([100, 140], v, amp)
        assert abs(np.log(a140 / a100) - 1.5 * np.log(1.4)) < 0.05, c["class"]
        assert all(lo_ <= a <= hi_ for lo_, a, hi_ in zip(c["low"], c["amplitude"], c["high"], strict=True))
    assert {o["wheel"] for o in body["wheel_offsets"]} == {"11", "12", "41", "42"}
    assert all(abs(o["offset"]) < 0.03 for o in body["wheel_offsets"])  # no sensor is off
    again = get(client, "/analytics/reference-curves", line_id=LINE_ID)
    assert again["computed_at"] == body["computed_at"] and again["track"] == TRACK  # cached
    r = client.post("/api/v1/analytics/reference-curves/refresh", params={"line_id": LINE_ID, "track": TRACK})
    assert r.status_code == 200 and r.json()["computed_at"] != body["computed_at"]
    assert client.get("/api/v1/analytics/reference-curves").status_code == 422


def test_index_agrees_across_speeds_while_the_amplitude_does_not(api, sim_set):
    client, ids = api
    a = pd.DataFrame(_profile(client, ids["A"], wheel="11")["rows"]).set_index("bin")
    c_body = _profile(client, ids["C"], wheel="11")
    ref = c_body["reference"]
    assert ref["available"] and ref["line_id"] == LINE_ID and sorted(ref["run_ids"]) == sorted(ids.values())
    c = pd.DataFrame(c_body["rows"]).set_index("bin")
    common = a.index.intersection(c.index)
    ia, ic = a.loc[common, "stiffness_index"].astype(float), c.loc[common, "stiffness_index"].astype(float)
    ok = np.isfinite(ia) & np.isfinite(ic)
    assert ok.mean() > 0.8
    assert np.corrcoef(ia[ok], ic[ok])[0, 1] > 0.95
    assert np.median(np.abs(ia[ok] - ic[ok])) < 0.05
    raw = np.log(c.loc[common, "sleeper_amp"][ok]) - np.log(a.loc[common, "sleeper_amp"][ok])
    assert np.median(raw) > 0.4  # 1.4 ** 1.5: the raw amplitude differs by half
    # the index is ln(A / A_ref) and has an uncertainty
    row = a.loc[common[ok.to_numpy()][0]]
    assert np.isclose(row["stiffness_index"], np.log(row["sleeper_amp"] / row["reference_amp"]))
    assert 0 < row["stiffness_index_se"] < 0.5
    # the soft and hard spots show in the index of both runs
    for an in sim_set.line.anomalies:
        core = (common.to_numpy() + 0.5) * 0.25
        inside = ok.to_numpy() & (core > an.track_from_m + an.taper_m + 20) & (core < an.track_to_m - an.taper_m - 20)
        if inside.sum() > 40:
            assert np.sign(np.median(ic[inside])) == np.sign(an.factor - 1), an


def test_index_in_aggregates_decimated_rows_and_exports(api):
    client, ids = api
    seg = _profile(client, ids["A"], wheel="12", level=10, columns="sleeper_amp")
    assert {"stiffness_index_mean", "stiffness_index_se_mean", "reference_amp_mean"} <= set(seg["columns"])
    few = _profile(client, ids["A"], wheel="12", max_points=500, columns="sleeper_amp")
    assert few["n_rows"] <= 500 and "stiffness_index" in few["columns"]
    plain = get(client, f"/runs/{ids['A']}/profile", wheel="12", max_points=500)
    assert "stiffness_index" not in plain["columns"] and plain["reference"] is None
    r = client.get(f"/api/v1/runs/{ids['A']}/profile.csv", params={"wheel": "12", "index": "true"})
    assert r.status_code == 200
    df = pd.read_csv(io.StringIO(r.text))
    assert {"stiffness_index", "stiffness_index_se", "reference_amp"} <= set(df.columns)
    assert np.isfinite(df["stiffness_index"]).mean() > 0.8
    r = client.get(f"/api/v1/runs/{ids['A']}/profile.parquet", params={"index": "true", "level": 100})
    pq = pd.read_parquet(io.BytesIO(r.content))
    assert "stiffness_index_mean" in pq.columns and set(pq["wheel"]) == {"11", "12", "41", "42"}


def test_power_law_is_flagged_and_superstructure_uses_the_index(api):
    client, ids = api
    body = get(client, "/analytics/speed-normalisation", line_id=LINE_ID, track=TRACK)
    assert "stiffness index" in body["note"]
    fits = {t["type"]: t for t in body["types"]}
    # two speeds, 100 and 140 km/h: within locations ln v spreads by ~0.16, a stable power law here
    for t in fits.values():
        assert isinstance(t["stable"], bool) and t["log_speed_std"] is not None
        if t["type"] != "*" and t["n_samples"] > 2000:
            assert t["stable"], t
            assert t["power_law_misfit"] is not None and t["power_law_misfit"] < 0.15
    one = get(client, "/analytics/speed-normalisation", line_id=LINE_ID, run_ids=str(ids["C"]))
    assert all(not t["stable"] for t in one["types"])  # one constant speed: nothing to estimate
    sup = get(client, "/analytics/superstructure", line_id=LINE_ID, track=TRACK)
    assert sup["normalised"] and sup["conditioning"] == "index"
    plaw = get(client, "/analytics/superstructure", line_id=LINE_ID, track=TRACK, conditioning="power_law")
    assert plaw["conditioning"] == "power_law"
    a = {t["type"]: t["median"] for t in sup["types"]}
    b = {t["type"]: t["median"] for t in plaw["types"]}
    for t in a:  # both condition to 100 km/h: the same type levels
        assert abs(np.log(a[t] / b[t])) < 0.05, (t, a[t], b[t])


def test_curves_go_stale_with_a_new_run_and_without_line(make_client, sim_set):
    client = make_client()
    first = store_run(client, sim_set.runs["A"])
    body = get(client, "/analytics/reference-curves", line_id=LINE_ID)
    assert body["run_ids"] == [first] and body["classes"]
    assert all(c["method"] == "pooled" for c in body["classes"])  # one run: one pass per location
    second = store_run(client, sim_set.runs["C"])
    again = get(client, "/analytics/reference-curves", line_id=LINE_ID)
    assert sorted(again["run_ids"]) == sorted([first, second]) and again["computed_at"] != body["computed_at"]
    viewer = make_client(role="viewer")
    r = viewer.post("/api/v1/analytics/reference-curves/refresh", params={"line_id": LINE_ID})
    assert r.status_code in (401, 403)


def test_segments_compare_runs_only_at_matched_speed(api):
    client, ids = api
    both = get(client, "/analytics/segments", line_id=LINE_ID, track=TRACK, run_ids=f"{ids['A']},{ids['C']}")
    assert both["value"] == "amplitude" and both["speed_tolerance"] == 0.1
    speeds = np.array(both["speed_kmh"], float)
    assert np.nanmedian(speeds[0]) == pytest.approx(100, abs=1) and np.nanmedian(speeds[1]) == pytest.approx(140, abs=1)
    assert all(c is None for c in both["change"])  # 100 vs 140 km/h: not compared
    same = get(client, "/analytics/segments", line_id=LINE_ID, track=TRACK, run_ids=f"{ids['A']},{ids['B']}")
    assert np.isfinite(np.array(same["change"], float)).mean() > 0.8
    idx = get(client, "/analytics/segments", line_id=LINE_ID, track=TRACK, run_ids=f"{ids['A']},{ids['C']}",
              value="index", align="false")
    m = np.array(idx["matrix"], float)
    ok = np.isfinite(m).all(axis=0)
    assert ok.mean() > 0.7 and np.median(np.abs(m[0, ok] - m[1, ok])) < 0.03  # the index agrees across speeds
    trend = get(client, "/analytics/segment-trend", line_id=LINE_ID, track=TRACK, km=12.95, value="index")
    assert trend["value"] == "index" and all(p["index"] is not None and p["speed_kmh"] > 90 for p in trend["points"])
