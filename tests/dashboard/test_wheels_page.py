"""The Wheels page shows the wheel flats of a run, in a real headless Chromium against the real service.

The demo (tests/dashboard/conftest.py) gives wheel 41 of vehicle SIM-1 a 40 mm, 0.2 mm flat from its
second run on: the third run's page lists it, marks it on the plots of r(θ) and says it was first
seen in the second run; the first run has none.
"""

from __future__ import annotations

import math

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
    assert f"run {dashboard.run_ids[1]}" in cells[6]  # first seen in the second run
    names = page.evaluate("document.getElementById('polar-plot').data.map(t => t.name)")
    assert "wheel flat" in names
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
