"""The Condition page in a real headless Chromium against the real service holding a generated
year of a line (``ingest_fleet``, with maintenance actions and sections) and one processed run of
that line (25 cm rows: the work list links open its stiffness map)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator

import numpy as np
import pytest

from tests.dashboard.conftest import PageLog, save_screenshot
from tests.e2e.conftest import running_service

pytestmark = pytest.mark.timeout(600)

ADMIN, PASSWORD = "cond-admin", "condition page password"
LINE = "CF"


@pytest.fixture(scope="module")
def condition_service(tmp_path_factory) -> Iterator[object]:
    from app.condition.fleet import ingest_fleet
    from app.db import auth_crud
    from app.db.session import Database
    from app.simulate.fleet import (
        FleetPlan,
        FleetSimulator,
        PlantedAction,
        PlantedStep,
        PlantedTrend,
    )
    from app.simulate.track import generate_line
    from tests.condition.support import publish_tracks

    work = tmp_path_factory.mktemp("condition-page")
    # the page's webhook form registers a receiver on loopback: allow-listed (SSRF policy, issue 24)
    with running_service(work / "service", env_overrides={"TRACKVKF_WEBHOOK_ALLOWED_NETWORKS": "127.0.0.1/32"}) as svc:
        db = Database(svc.database_url)
        plan = FleetPlan(steps=(PlantedStep(2_400.0, 2_420.0, day=70.0, factor=1.25),),
                         trends=(PlantedTrend(3_300.0, 3_700.0, day=20.0, rate_per_year=0.4),),
                         actions=(PlantedAction(1_000.0, 1_300.0, day=40.0),))
        sim = FleetSimulator(generate_line(0.0, 5_000.0, seed=41), plan)
        start = dt.datetime(2025, 1, 6, 8, 0, tzinfo=dt.UTC)
        ingest_fleet(db, sim, 80, line_id=LINE, start=start, seed=42)
        _, tracks = FleetSimulator(sim.line, plan, grid_m=0.25).run(80.0, np.random.default_rng(43))
        run_id, _, _ = publish_tracks(db, tracks, start + dt.timedelta(days=80), line_id=LINE)
        with db.write() as s:
            auth_crud.create_user(s, ADMIN, PASSWORD, "admin")
        db.dispose()
        svc.map_run_id = run_id
        yield svc


@pytest.fixture
def admin_page(browser, condition_service):
    ctx = browser.new_context(base_url=condition_service.base_url, viewport={"width": 1400, "height": 900})
    ctx.set_default_timeout(60_000)
    r = ctx.request.post("/api/v1/auth/login", data={"username": ADMIN, "password": PASSWORD})
    assert r.status == 200, r.text()
    page = ctx.new_page()
    log = PageLog(origin=condition_service.base_url)
    log.attach(page)
    try:
        yield page, log
    finally:
        ctx.close()


def _plot(page, plot_id: str) -> dict:
    return page.evaluate(f"""() => {{ const el = document.getElementById('{plot_id}');
        return {{ state: el.dataset.state || '', points: Number(el.dataset.points || 0), traces: el.data ? el.data.length : 0,
                 xtitle: el.layout && el.layout.xaxis.title ? el.layout.xaxis.title.text : null,
                 ytitle: el.layout && el.layout.yaxis.title ? el.layout.yaxis.title.text : null,
                 csv: !!document.querySelector(`button[data-csv-for="{plot_id}"]:not([disabled])`) }}; }}""")


def test_condition_page_shows_the_line_with_data(admin_page, condition_service):
    page, log = admin_page
    page.goto("/condition")
    page.wait_for_selector("body[data-ready='1']")
    for plot_id in ("cond-heatmap", "cond-trend", "cond-effect"):
        p = _plot(page, plot_id)
        assert p["state"] == "ready" and p["traces"] > 0 and p["points"] > 0 and p["csv"], (plot_id, p)
        assert p["xtitle"] and p["ytitle"], (plot_id, p)
    heat = page.evaluate("document.getElementById('cond-heatmap').data")
    assert len(heat[0]["y"]) == 81 and len(heat[0]["x"]) == 50  # 81 runs x 50 segments of 100 m
    assert len(heat[1]["x"]) > 0  # flagged cells marked
    rows = page.locator("#worklist-body tr[data-km]")
    assert rows.count() > 0
    kms = [float(x) for x in page.eval_on_selector_all("#worklist-body tr[data-km]", "r => r.map(x => x.dataset.km)")]
    assert any(2.39 <= k < 2.43 for k in kms) or any(3.3 <= k < 3.7 for k in kms)  # a planted change is listed
    link = page.locator("#worklist-body a", has_text="Stiffness map").first
    assert link.get_attribute("href").startswith(f"/runs/{condition_service.map_run_id}?km_from=")
    assert page.locator("#actions-body tr[data-action]").count() == 1
    assert "tamping" in page.inner_text("#effect-title")
    rows.first.locator("button[data-act='trend']").click()
    first_km = float(rows.first.get_attribute("data-km"))
    page.wait_for_function("(km) => document.getElementById('cond-trend-title').textContent.includes(km)",
                           arg=f"{first_km:.3f}")
    assert page.locator("#webhooks-card").is_visible()
    page.fill("#webhook-url", "http://127.0.0.1:9/hook")
    page.click("#webhook-form button[type=submit]")
    page.wait_for_function("() => document.getElementById('webhook-secret').textContent.includes('whsec_')")
    page.wait_for_selector("#webhooks-body tr[data-hook]")
    assert page.locator("#webhooks-body tr[data-hook]").count() == 1
    assert page.locator("#banner").is_hidden()
    save_screenshot(page, "condition")
    log.assert_clean()
    assert not log.foreign()


def test_the_work_list_link_opens_the_stiffness_map_at_that_km(admin_page, condition_service):
    page, log = admin_page
    page.goto("/condition")
    page.wait_for_selector("body[data-ready='1']")
    href = page.locator("#worklist-body a", has_text="Stiffness map").first.get_attribute("href")
    page.goto(href)
    page.wait_for_selector("body[data-ready='1']")
    km_from = float(href.split("km_from=")[1].split("&")[0])
    page.wait_for_function("(km) => Math.abs(parseFloat(document.querySelector('#km-from').value) - km) < 0.002",
                           arg=km_from)
    log.assert_clean()


def test_a_bad_webhook_url_shows_the_api_message(admin_page):
    page, log = admin_page
    page.goto("/condition")
    page.wait_for_selector("body[data-ready='1']")
    page.evaluate("document.getElementById('webhook-url').type = 'text'")  # let the browser send it
    page.fill("#webhook-url", "ftp://example.org/x")
    page.click("#webhook-form button[type=submit]")
    banner = page.locator("#banner")
    banner.wait_for(state="visible")
    assert "422" in banner.inner_text() and "url:" in banner.inner_text()
    assert all("/api/v1/webhooks" in f and "422" in f for f in log.failed), log.failed
