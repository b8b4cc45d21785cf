"""The condition endpoints on a generated fleet history: lines, heat map, trend, change lists,
the flag feed, and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.condition.conftest import FLEET_LINE, FLEET_RUNS


def test_lines_list_the_store(fleet):
    r = fleet.client.get("/api/v1/condition/lines")
    assert r.status_code == 200, r.text
    items = {(i["line_id"], i["track"]): i for i in r.json()["items"]}
    assert set(items) == {(FLEET_LINE, "1"), ("F2", "1"), ("F2", "2")}
    f1 = items[(FLEET_LINE, "1")]
    assert f1["n_runs"] == FLEET_RUNS and f1["first_run"].startswith("2025-03-01")
    assert 10.0 <= f1["km_min"] < 10.1 and 13.9 < f1["km_max"] <= 14.0


def test_heatmap_runs_by_km_with_flags(fleet):
    r = fleet.client.get("/api/v1/condition/heatmap", params={"line_id": FLEET_LINE})
    assert r.status_code == 200, r.text
    hm = r.json()
    assert hm["segment_m"] == 100 and hm["wheel"] is None and hm["condition_index"] == "ln_amplitude"
    assert len(hm["runs"]) == FLEET_RUNS and len(hm["km"]) == 40
    assert [x["start_time"] for x in hm["runs"]] == sorted(x["start_time"] for x in hm["runs"])
    assert all(len(row) == 40 for row in hm["matrix"])
    values = [v for row in hm["matrix"] for v in row if v is not None]
    assert len(values) > 0.95 * FLEET_RUNS * 40 and all(math.isfinite(v) for v in values)
    # the planted tamping (km 13.0-13.3 from day 30) is a flagged cell in run 30
    col = hm["km"].index(13.0)
    assert [30, col] in hm["flagged"]
    one = fleet.client.get("/api/v1/condition/heatmap", params={
        "line_id": FLEET_LINE, "segment_m": 10, "wheel": "Z12", "km_from": 11.0, "km_to": 11.5,
        "date_from": "2025-03-10", "date_to": "2025-03-19"}).json()
    assert one["wheel"] == "12" and len(one["km"]) == 50 and len(one["runs"]) == 10
    assert one["km"][0] == pytest.approx(11.0) and one["km"][-1] == pytest.approx(11.49)


def test_trend_of_a_segment_with_the_maintenance_action(fleet):
    r = fleet.client.get("/api/v1/condition/trend", params={"line_id": FLEET_LINE, "km": 13.105})
    assert r.status_code == 200, r.text
    t = r.json()
    assert t["segment_km"] == pytest.approx([13.1, 13.11]) and t["segment_m"] == 10
    assert len(t["points"]) == FLEET_RUNS
    assert [a["type"] for a in t["maintenance"]] == ["tamping"] and t["maintenance"][0]["date"] == "2025-03-31"
    p = t["points"]
    before = sum(x["condition_index"] for x in p[20:30]) / 10
    after = sum(x["condition_index"] for x in p[30:40]) / 10
    assert after - before == pytest.approx(math.log(0.85), abs=0.05)  # the recovery
    assert p[30]["flagged"] and len(p[30]["wheels"]) == 4
    w = p[30]["wheels"][0]
    assert w["change"] < -0.08 and w["change_z"] < -2 and 8 <= w["n_history"] <= 30 and w["speed_kmh"] > 90


def test_change_lists_of_the_newest_run_and_of_a_run(fleet):
    newest = fleet.client.get("/api/v1/condition/changes", params={"line_id": FLEET_LINE}).json()
    assert newest["start_time"].startswith("2025-04-29")
    scores = [abs(f["score"]) for f in newest["items"]]
    assert scores == sorted(scores, reverse=True)
    trend = [f for f in newest["items"] if f["kind"] == "trend"]
    assert any(12.3 <= f["km_from"] < 12.7 and f["direction"] == "up" for f in trend)  # the planted trend
    # the tamping of day 30 is a step, not a trend (the data after it are flat or growing back)
    assert not any(12.9 <= f["km_from"] < 13.3 for f in trend)
    lines = fleet.client.get("/api/v1/condition/lines").json()["items"]
    run_id = next(i["last_run_id"] for i in lines if i["line_id"] == FLEET_LINE) - (FLEET_RUNS - 1 - 45)
    step = fleet.client.get(f"/api/v1/condition/runs/{run_id}/changes").json()
    hits = [f for f in step["items"] if f["kind"] == "step" and f["segment_m"] == 10 and 11.49 <= f["km_from"] < 11.53]
    assert hits and all(f["is_new"] and f["direction"] == "up" for f in hits)
    assert max(f["change_pct"] for f in hits) == pytest.approx(20, abs=6)
    assert fleet.client.get("/api/v1/condition/runs/999999/changes").status_code == 404


def test_the_flag_feed_pages_without_gaps(fleet):
    seen, since = [], 0
    while True:
        page = fleet.client.get("/api/v1/condition/flags", params={"since": since, "limit": 37}).json()
        if not page["items"]:
            assert page["next_since"] == since
            break
        ids = [f["id"] for f in page["items"]]
        assert ids == sorted(ids) and ids[0] > since and page["next_since"] == ids[-1]
        seen += ids
        since = page["next_since"]
    assert len(seen) == len(set(seen)) > 10
    new = fleet.client.get("/api/v1/condition/flags", params={"since": 0, "limit": 1000, "new_only": True,
                                                               "line_id": FLEET_LINE}).json()["items"]
    assert new and all(f["is_new"] and f["line_id"] == FLEET_LINE for f in new)


@pytest.mark.parametrize(("path", "params", "status", "field"), [
    ("heatmap", {"line_id": "nope"}, 404, "line_id"),
    ("heatmap", {"line_id": FLEET_LINE, "track": "9"}, 404, "line_id"),
    ("heatmap", {"line_id": "F2"}, 422, "track"),
    ("heatmap", {"line_id": FLEET_LINE, "segment_m": 20}, 422, "segment_m"),
    ("heatmap", {"line_id": FLEET_LINE, "km_from": 20.0}, 422, "km_from"),
    ("heatmap", {"line_id": FLEET_LINE, "km_from": 12.0, "km_to": 11.0}, 422, "km_from"),
    ("heatmap", {"line_id": FLEET_LINE, "wheel": "13"}, 422, "wheel"),
    ("heatmap", {"line_id": FLEET_LINE, "date_from": "yesterday"}, 422, "date_from"),
    ("trend", {"line_id": FLEET_LINE, "km": 9.5}, 422, "km"),
    ("trend", {"line_id": "nope", "km": 12.0}, 404, "line_id"),
    ("changes", {"line_id": "nope"}, 404, "line_id"),
    ("flags", {"line_id": "nope"}, 404, "line_id"),
])
def test_bad_input_names_the_field(fleet, path, params, status, field):
    r = fleet.client.get(f"/api/v1/condition/{path}", params=params)
    assert r.status_code == status, r.text
    assert r.json()["field"] == field and r.json()["detail"].startswith(f"{field}: ")


@pytest.mark.parametrize("path", ["hotspots", "hotspots.csv", "hotspots.geojson"])
def test_the_retired_hotspot_list_answers_gone_naming_the_places(fleet, path):
    r = fleet.client.get(f"/api/v1/condition/{path}", params={"line_id": FLEET_LINE})
    assert r.status_code == 410, r.text
    assert r.json()["field"] == "path" and "/api/v1/condition/places" in r.json()["detail"]
    assert r.headers["link"] == '</api/v1/condition/places>; rel="alternate"'


def test_maintenance_effect_of_the_planted_tamping(fleet):
    r = fleet.client.get("/api/v1/condition/maintenance-effect", params={"line_id": FLEET_LINE})
    assert r.status_code == 200, r.text
    (item,) = r.json()["items"]
    assert item["type"] == "tamping" and item["date"] == "2025-03-31"
    assert item["n_runs_before"] == 31 and item["n_runs_after"] == 29  # runs at 08:00, the action at noon
    assert item["recovery"] == pytest.approx(math.log(0.85 + 0.3 * 15 / 365.25), abs=0.03)
    assert item["recovery_pct"] < -10
    assert item["slope_after_per_year"] == pytest.approx(0.3 / 0.87, abs=0.15)
    assert item["lasted_days_observed"] is None  # a month of data after it: not lost yet
    # projected to be half lost beyond the month the runs saw: not said (issue 34 item 5)
    assert item["followed_days"] == pytest.approx(29 - 1 / 6, abs=0.01) and item["lasted_days_projected"] is None
    assert item["recovery_low"] < item["recovery"] < item["recovery_high"]
    assert item["support_change"] == item["recovery"] and item["rail_surface"] is False
    assert item["sign_convention"].startswith("after - before") and item["interval"] == "1 sigma (68 %)"
    d = fleet.client.get(f"/api/v1/condition/maintenance-effect/{item['action_id']}").json()
    assert len(d["series"]) == FLEET_RUNS and d["recovery"] == item["recovery"]
    assert d["profile_km"][0] == pytest.approx(12.9) and d["profile_km"][-1] == pytest.approx(13.4)
    inside = [b - a for k, a, b in zip(d["profile_km"], d["profile_before"], d["profile_after"], strict=True)
              if 13.0 <= k < 13.29]
    outside = [b - a for k, a, b in zip(d["profile_km"], d["profile_before"], d["profile_after"], strict=True)
               if k < 12.98 or k > 13.31]
    assert np.mean(inside) < -0.1 and abs(np.mean(outside)) < 0.03
    none = fleet.client.get("/api/v1/condition/maintenance-effect", params={"line_id": FLEET_LINE,
                                                                           "type": "grinding"}).json()
    assert none["items"] == []
    assert fleet.client.get("/api/v1/condition/maintenance-effect/99999").status_code == 404
    bad = fleet.client.get("/api/v1/condition/maintenance-effect", params={"line_id": FLEET_LINE, "type": "x"})
    assert bad.status_code == 422 and bad.json()["field"] == "type"
