"""The map page: a line geometry with the latest run's indicator coloured along it (no tiles),
and a click on a segment opening that run's stiffness map at the segment's km."""

from __future__ import annotations

import json
import re
from urllib.parse import parse_qs, urlsplit

import pytest

from app.simulate.geometry import synthetic_line
from tests.dashboard.conftest import save_screenshot


@pytest.fixture(scope="module")
def geometry_id(dashboard) -> int:
    _, doc = synthetic_line(11.8, 13.5, seed=4, line_id="SIM", track="1")  # the fixture runs' line
    with dashboard.service.client(timeout=60) as client:
        r = client.post("/api/v1/geometry",
                        files={"file": ("sim.geojson", json.dumps(doc).encode(), "application/geo+json")})
        assert r.status_code == 201, r.text
        return r.json()["imported"][0]["id"]


def test_map_shows_indicator_and_click_opens_the_stiffness_map(open_page, dashboard, geometry_id):
    page, log = open_page(f"/map?geometry_id={geometry_id}")
    state = page.evaluate("""() => {
      const el = document.getElementById('map-plot');
      return {traces: el.data.length, types: el.data.map(t => t.type),
              line: el.data[0].x.length, points: el.data[1].x.length,
              colors: el.data[1].marker.color.filter(v => v !== null).length,
              runs: [...new Set(el.data[1].customdata.map(c => c[0]))],
              xtitle: el.layout.xaxis.title.text, ytitle: el.layout.yaxis.title.text,
              km: (el.data.find(t => t.name === 'km') || {text: []}).text,
              places: (el.data.find(t => t.name === 'places') || {customdata: []}).customdata.map(c => c[1]),
              csv: !document.querySelector('[data-csv-for="map-plot"]').disabled};
    }""")
    # the line and its indicator first, then the km marks (and the places where there are any)
    assert state["types"][:2] == ["scatter", "scatter"] and set(state["types"]) == {"scatter"} and state["line"] > 10
    assert len(state["km"]) >= 2 and all(re.fullmatch(r"km \d+(\.\d)?", t) for t in state["km"]), state["km"]
    with dashboard.service.client(timeout=60) as client:
        places = client.get("/api/v1/condition/places", params={"line_id": "SIM", "track": "1", "limit": 500}).json()
    on_line = sorted(p["id"] for p in places.get("items", []) if 11.8 <= p["peak_km"] <= 13.5)
    assert sorted(state["places"]) == on_line, (state["places"], on_line)
    assert state["points"] >= 8 and state["colors"] == state["points"], state  # 1.2 km in 100 m segments
    with dashboard.service.client(timeout=60) as client:  # newest start first
        latest = client.get("/api/v1/runs", params={"line_id": "SIM", "track": "1"}).json()["items"][0]["id"]
    assert state["runs"] == [latest]
    assert "(km)" in state["xtitle"] and "(km)" in state["ytitle"] and state["csv"]
    assert "no basemap" in page.inner_text("#map-info")
    save_screenshot(page, "map")
    # a real click on the middle marker
    x, y, km_from, km_to = page.evaluate("""() => {
      const el = document.getElementById('map-plot'), L = el._fullLayout, t = el.data[1];
      const i = Math.floor(t.x.length / 2), box = el.getBoundingClientRect();
      return [box.left + L.xaxis._offset + L.xaxis.l2p(t.x[i]),
              box.top + L.yaxis._offset + L.yaxis.l2p(t.y[i]), t.customdata[i][2], t.customdata[i][3]];
    }""")
    with page.expect_navigation():
        page.mouse.click(x, y)
    url = urlsplit(page.url)
    assert url.path == f"/runs/{latest}"
    q = parse_qs(url.query)
    assert float(q["km_from"][0]) <= km_from and float(q["km_to"][0]) >= km_to
    page.wait_for_selector("body[data-ready='1']")
    shown = page.evaluate("document.getElementById('stiffness-plot').layout.xaxis.range")
    assert shown[0] <= km_to and shown[1] >= km_from
    log.assert_clean()
    assert not log.foreign()


def test_map_page_boot_carries_the_tile_setting(make_client):
    for tile in (None, "https://tiles.example/{z}/{x}/{y}.png"):
        client = make_client(**({"map_tile_url": tile} if tile else {}))
        html = client.get("/map").text
        boot = json.loads(html.split('<script id="boot" type="application/json">')[1].split("</script>")[0])
        assert (boot["tiles"] or {}).get("url") == tile
