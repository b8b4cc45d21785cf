"""The Wheels page shows the wheel flats of a run, in a real headless Chromium against the real service.

The demo (tests/dashboard/conftest.py) gives wheel 41 of vehicle SIM-1 a 40 mm, 0.2 mm flat from its
second run on: the third run's page lists it, marks it on the plots of r(θ) and says when it was first
seen (the earliest of the unbroken series of SIM-1's runs with a flat on wheel 41: the second run,
unless the upload test's run of SIM-1, without flats, came in between); the first run has none.
"""

from __future__ import annotations

import math

import httpx
import pytest

pytestmark = pytest.mark.timeout(300)


def _open(open_page, dashboard, run_index: int):
    page, log = open_page(f"/wheels?vehicle_id=SIM-1&run_id={dashboard.run_ids[run_index]}")
    page.wait_for_function("() => !document.querySelector('#flats-body').textContent.includes('–')")
    return page, log


def test_a_wheel_flat_is_listed_and_marked(open_page, dashboard):
    page, log = _open(open_page, dashboard, 2)
    rows = page.locator("#flats-body tr")
    assert rows.count() == 1
    cells = [c.strip() for c in rows.nth(0).locator("td").all_inner_texts()]
    assert cells[0].endswith("Z41")
    assert abs(float(cells[1]) - math.degrees(1.0)) < 3.0  # the simulator's flat at θ = 1 rad
    assert 0.1 <= float(cells[3]) <= 0.3  # 0.2 mm deep
    with httpx.Client(base_url=dashboard.base_url, headers=dashboard.service.headers) as client:
        second = client.get(f"/api/v1/runs/{dashboard.run_ids[1]}/wheels").json()["items"]
        trend = client.get("/api/v1/wheels/trend", params={"vehicle_id": "SIM-1", "wheel": "41"}).json()["items"]
    assert next(w for w in second if w["wheel"] == "41")["flat"] is not None  # found in the second run too
    at = [i["run_id"] for i in trend].index(dashboard.run_ids[2])
    first = at
    while first > 0 and trend[first - 1]["flat_depth_mm"] is not None:
        first -= 1
    want = "this run" if first == at else f"run {trend[first]['run_id']}"
    assert want in cells[6]
    theta, r, rng = page.evaluate("(() => { const el = document.getElementById('polar-plot'); "
                                  "const t = el.data.find(t => t.name === 'wheel flat'); "
                                  "return [t.theta, t.r, el.layout.polar.radialaxis.range]; })()")
    assert r[1] == rng[1] and abs(theta[1] - float(cells[1])) < 0.1  # marked on the rim at its angle
    shapes = page.evaluate("(document.getElementById('profile-plot').layout.shapes || []).length")
    assert shapes == 1
    plots = page.evaluate("Array.from(document.querySelectorAll('.plot')).map(el => [el.id, el.dataset.state, "
                          "el.data ? el.data.length : 0])")
    assert all(state == "ready" and traces > 0 for _, state, traces in plots), plots
    assert page.inner_text("#banner").strip() == ""
    log.assert_clean()


def test_a_run_without_flat_says_so(open_page, dashboard):
    page, log = _open(open_page, dashboard, 0)
    assert "No wheel flat found" in page.inner_text("#flats-body")
    names = page.evaluate("document.getElementById('polar-plot').data.map(t => t.name)")
    assert "wheel flat" not in names and len(names) == 4
    log.assert_clean()
