"""Every dashboard page in a real headless Chromium against the real service."""

from __future__ import annotations

import csv
import io
import re

import httpx
import pytest

pytestmark = pytest.mark.timeout(300)


def _pages(dashboard) -> list[tuple[str, str]]:
    first = dashboard.run_ids[0]
    return [
        ("runs", "/"),
        ("stiffness-map", f"/runs/{first}"),
        ("spectrogram", f"/runs/{first}/spectrogram?wheel=12"),
        ("line-view", "/lines"),
        ("wheels", "/wheels"),
        ("correlations", "/correlations"),
    ]


def _plots(page) -> list[dict]:
    return page.evaluate(
        """() => Array.from(document.querySelectorAll('.plot')).map(el => ({
            id: el.id, state: el.dataset.state || '', points: Number(el.dataset.points || 0),
            traces: el.data ? el.data.length : 0,
            modebarPng: Array.from(el.querySelectorAll('.modebar-btn')).some(
                b => (b.getAttribute('data-title') || '').toLowerCase() === 'download plot as a png'),
            modebarCloud: Array.from(el.querySelectorAll('.modebar-btn')).some(
                b => (b.getAttribute('data-title') || '').toLowerCase().includes('share')),
            csvEnabled: !!document.querySelector(`button[data-csv-for="${el.id}"]:not([disabled])`),
            xtitle: el.layout && el.layout.xaxis && el.layout.xaxis.title ? el.layout.xaxis.title.text : null,
            ytitle: el.layout && el.layout.yaxis && el.layout.yaxis.title ? el.layout.yaxis.title.text : null,
        }))"""
    )


@pytest.mark.parametrize(
    "name", ["runs", "stiffness-map", "spectrogram", "line-view", "wheels", "correlations"]
)
def test_page_loads_clean_with_data(open_page, dashboard, name):
    path = dict(_pages(dashboard))[name]
    page, log = open_page(path)
    plots = _plots(page)
    if name == "correlations":
        # the demo's reference data of line SIM (the default line: most processed runs) fill
        # every panel; the simulated runs have force channels, so the unsprung mass is fitted
        state = {p["id"]: p for p in plots}
        for plot_id in ("subsidence-plot", "maintenance-plot"):
            assert state[plot_id]["state"] == "ready" and state[plot_id]["points"] > 0
        assert "Z11" in page.inner_text("#fit-table") and "No fit" not in page.inner_text("#fit-table")
        assert page.input_value("#line-track").startswith("SIM\u0001")
        mass = state["mass-plot"]
        assert mass["state"] == "ready" and mass["points"] > 0 and mass["modebarPng"] and mass["csvEnabled"]
        names = page.evaluate("document.getElementById('mass-plot').data.map(t => t.name)")
        masses = [float(n.split(": ")[1].split(" kg")[0]) for n in names if n and " kg" in n]
        assert len(masses) == 4
        assert all(abs(m - 300.0) < 45.0 for m in masses), masses  # simulator: 300 kg
    elif name != "runs":
        assert plots, f"{name}: no plot"
        for p in plots:
            assert p["state"] == "ready" and p["traces"] > 0 and p["points"] > 0, p
            assert p["modebarPng"], f"{p['id']}: no PNG download button"
            assert not p["modebarCloud"], f"{p['id']}: a button that sends the chart outside"
            assert p["csvEnabled"], f"{p['id']}: no Download CSV button"
            if p["id"] != "polar-plot":
                assert p["xtitle"] and p["ytitle"] and "(" in p["ytitle"], f"{p['id']}: axis titles {p}"
    else:
        rows = page.locator("#runs-body tr[data-run]")
        assert rows.count() >= len(dashboard.run_ids)
        assert page.locator("#runs-body .badge.done").count() >= len(dashboard.run_ids)
    log.assert_clean()
    assert not log.foreign()


def test_all_requests_go_to_own_origin(open_page, dashboard):
    """Zoom the stiffness map: every request URL, the page's and the zoom's, is on the app's origin
    (each page's requests as it loads: test_page_loads_clean_with_data and the walk)."""
    page, log = open_page(dict(_pages(dashboard))["stiffness-map"])
    page.fill("#km-from", "12.4")
    page.fill("#km-to", "12.6")
    page.click("#map-controls button[type=submit]")
    page.wait_for_function("() => document.querySelector('#km-from').value === '12.400'")
    seen = log.requests
    assert not log.foreign(), f"requests outside the server: {log.foreign()}"
    log.assert_clean()
    assert any(u.endswith("/vendor/plotly.min.js") for u in seen)
    assert any("/api/v1/" in u for u in seen)
    assert all(u.startswith(dashboard.base_url) or u.startswith(("blob:", "data:")) for u in seen)


def test_stiffness_map_zoom_refetches_decimated_range(open_page, dashboard):
    page, log = open_page(f"/runs/{dashboard.run_ids[0]}")
    # the run's speeds as the API answers them (km/h), shown without a conversion of the page's own
    summary = page.evaluate(f"fetch('/api/v1/runs/{dashboard.run_ids[0]}').then((r) => r.json())")["summary"]
    shown = page.locator("#run-meta div", has_text="Speed").locator("b").inner_text()
    assert re.findall(r"\d+", shown) == [str(round(summary["speed_min_kmh"])), str(round(summary["speed_max_kmh"]))]
    assert 20 < summary["speed_min_kmh"] <= summary["speed_max_kmh"] < 400 and shown.endswith("km/h")
    whole = page.evaluate("document.getElementById('stiffness-plot').data[0].x.length")
    assert 100 < whole <= 4000  # 6000 bins of 25 cm decimated for display
    with page.expect_response(lambda r: "/profile?" in r.url and "km_from=12.5" in r.url):
        page.fill("#km-from", "12.5")
        page.fill("#km-to", "12.6")
        page.click("#map-controls button[type=submit]")
    page.wait_for_function("() => document.querySelector('#map-info').textContent.includes('12.500')")
    xs = page.evaluate("document.getElementById('stiffness-plot').data[0].x")
    assert 300 <= len(xs) <= 401  # 100 m of 25 cm bins: all of them, not decimated
    assert min(xs) >= 12.5 and max(xs) <= 12.6
    # the stiffness index by default, with the reference curves it used stated; raw amplitude one click away
    assert "index" in page.evaluate("document.getElementById('stiffness-plot').layout.yaxis.title.text")
    assert "Reference curves of line" in page.inner_text("#reference-info")
    page.select_option("#map-value", "amplitude")
    page.wait_for_function("() => document.getElementById('stiffness-plot').layout.yaxis.title.text.includes('m/s')")
    page.select_option("#amp-scale", "log")
    page.wait_for_function("() => document.getElementById('stiffness-plot').layout.yaxis.type === 'log'")
    with page.expect_download() as dl:
        page.click("button[data-csv-for='stiffness-plot']")
    text = dl.value.path().read_text()
    rows = list(csv.DictReader(io.StringIO(text)))
    assert rows and set(rows[0]) >= {"wheel", "km", "sleeper_amp_mps2", "speed_kmh", "stiffness_index"}
    assert {r["wheel"] for r in rows} == {"11", "12", "41", "42"}
    # the step estimate (sleeper_step, stored with the profile) one more click away: a named trace per wheel
    page.select_option("#map-value", "steps")
    page.wait_for_function("() => document.getElementById('stiffness-plot').data.some((t) => t.meta === 'step-estimate')")
    steps = page.evaluate("document.getElementById('stiffness-plot').data.filter((t) => t.meta === 'step-estimate')"
                          ".map((t) => ({name: t.name, y: t.y, shape: t.line.shape}))")
    assert steps and all(t["name"].endswith(": step estimate") and t["shape"] == "hv" for t in steps)
    for t in steps:
        finite = [y for y in t["y"] if y is not None]
        assert len(finite) >= 0.9 * len(t["y"]) > 300  # the zoomed 100 m: every bin with its level
        assert 1 <= len(set(finite)) < len(finite) / 12  # levels, not the amplitude's own fluctuation
    assert "step estimate" in page.inner_text("#map-title") and "change points" in page.inner_text("#reference-info")
    with page.expect_download() as dl:
        page.click("button[data-csv-for='stiffness-plot']")
    rows = list(csv.DictReader(io.StringIO(dl.value.path().read_text())))
    assert sum(1 for r in rows if r["sleeper_step_mps2"]) >= 0.9 * len(rows)
    log.assert_clean()


def test_upload_shows_job_finishing(open_page, dashboard):
    page, log = open_page("/")
    page.set_input_files("#upload-file", str(dashboard.upload_file))
    page.click("#upload-button")
    page.wait_for_function(
        "() => document.getElementById('upload-status').textContent.includes('done')", timeout=180_000
    )
    status = page.inner_text("#upload-status")
    assert "processing job" in status
    width = page.evaluate("document.querySelector('#upload-progress > span').style.width")
    assert width == "100%"
    run_id = int(status.split("Run ", 1)[1].split(":", 1)[0])
    row = page.locator(f"#runs-body tr[data-run='{run_id}'] .badge.done")
    row.wait_for()
    log.assert_clean()


def test_bad_file_shows_the_api_error(open_page, dashboard):
    with open(dashboard.bad_file, "rb") as fh:
        api = httpx.post(f"{dashboard.base_url}/api/v1/runs", files={"file": (dashboard.bad_file.name, fh)},
                         headers=dashboard.service.headers)
    assert api.status_code == 422
    detail = api.json()["detail"]
    page, log = open_page("/")
    page.set_input_files("#upload-file", str(dashboard.bad_file))
    page.click("#upload-button")
    banner = page.locator("#banner")
    banner.wait_for(state="visible")
    assert detail in banner.inner_text()
    assert "422" in banner.inner_text()
    assert page.inner_text("#upload-status") == "Upload rejected."
    # the only failure is the rejected upload itself
    assert all("/api/v1/runs" in f and "422" in f for f in log.failed), log.failed
    assert all("422" in e for e in log.console_errors), log.console_errors
    assert not log.page_errors


def test_reprocess_and_cancel_from_the_runs_page(open_page, dashboard):
    run_id = dashboard.run_ids[1]
    page, log = open_page("/")
    row = page.locator(f"#runs-body tr[data-run='{run_id}']")
    row.locator("button[data-act='reprocess']").click()
    page.wait_for_function("() => document.getElementById('banner').textContent.includes('reprocessing job')")
    banner = page.inner_text("#banner")
    job_id = int(banner.split("reprocessing job ", 1)[1].split(" ", 1)[0])
    cancel = page.locator(f"#runs-body tr[data-run='{run_id}'] button[data-act='cancel']")
    cancel.wait_for()
    cancel.click()
    page.wait_for_function(
        "() => document.getElementById('banner').textContent.includes('Cancel requested') || "
        "document.getElementById('banner').textContent.includes('already')"
    )
    job = httpx.get(f"{dashboard.base_url}/api/v1/jobs/{job_id}", headers=dashboard.service.headers).json()
    deadline = 120
    while job["status"] in ("queued", "running") and deadline > 0:
        page.wait_for_timeout(500)
        deadline -= 0.5
        job = httpx.get(f"{dashboard.base_url}/api/v1/jobs/{job_id}", headers=dashboard.service.headers).json()
    assert job["status"] in ("cancelled", "done") and job["cancel_requested"] in (True, job["status"] == "done")
    badge = page.locator(f"#runs-body tr[data-run='{run_id}'] .job-status .badge")
    page.wait_for_function(
        f"() => document.querySelector(\"#runs-body tr[data-run='{run_id}'] .job-status .badge\").textContent === '{job['status']}'"
    )
    assert badge.inner_text() == job["status"]
    if "already" in page.inner_text("#banner"):  # the job finished before the cancel reached it
        assert all("/cancel" in f and "409" in f for f in log.failed), log.failed
    else:
        log.assert_clean()


def test_pages_need_a_login(browser, dashboard):
    """Without a session every page goes to the login form, which comes back to the page."""
    ctx = browser.new_context(base_url=dashboard.base_url)
    try:
        page = ctx.new_page()
        page.goto("/wheels")
        assert page.url.startswith(f"{dashboard.base_url}/login?next=")
        page.fill("#username", "dash-engineer")
        page.fill("#password", "dashboard tests password")
        page.click("button[type=submit]")
        page.wait_for_url(f"{dashboard.base_url}/wheels")
        page.wait_for_selector("body[data-ready='1']")
    finally:
        ctx.close()
