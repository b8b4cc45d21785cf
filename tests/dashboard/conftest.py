"""Browser tests of the dashboard: Debian's chromium driven by Playwright against the real
service (uvicorn + worker subprocesses, tests/e2e/conftest.py) holding the demo data (short
runs): three processed runs of line SIM at three dates, one of line SIM-B, the reference data
of line SIM and the geometry of both lines, all uploaded and imported over HTTP and processed
once per session (tests/demo_db.py, shared with the golden identity test).

No browser is downloaded: /usr/bin/chromium comes from the Debian package, installed here
with apt-get when it is missing (the CI machine runs as root).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

import pytest

from tests.api.support import TEST_PASSWORD_COST
from tests.e2e.conftest import Service, running_service

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]
#: where the walk's screenshots go: a scratch folder, so that a test run leaves the checkout as it
#: was; ``TRACKVKF_SCREENSHOT_DIR=docs/screenshots scripts/test.sh tests/dashboard`` refreshes the
#: README's pictures
SCREENSHOTS = Path(os.environ.get("TRACKVKF_SCREENSHOT_DIR")
                   or Path(tempfile.gettempdir()) / f"trackvkf-screenshots-{os.getuid()}")
#: the extra run file of the upload test: sample rate (Hz) and the line it is on
RUN_FS = 10_000.0
LINE_SEED = 7
#: the browser's user: an engineer (uploads, reprocesses, cancels)
USER, PASSWORD = "dash-engineer", "dashboard tests password"


def _install_chromium() -> None:
    """apt-get install Debian's chromium (idempotent; only when /usr/bin/chromium is missing)."""
    from tests.system_packages import AptUnavailable, apt_install

    try:
        apt_install(["chromium", "fonts-dejavu-core"], installed=CHROMIUM.exists)
    except AptUnavailable as exc:
        pytest.fail(f"/usr/bin/chromium is missing: install the Debian package `chromium` ({exc})")


@dataclass
class Dashboard:
    """The running service with its processed runs."""

    service: Service
    run_ids: list[int]
    upload_file: Path
    bad_file: Path

    @property
    def base_url(self) -> str:
        return self.service.base_url


@pytest.fixture(scope="session")
def dashboard(tmp_path_factory, processed_demo) -> Iterator[Dashboard]:
    """The real service (uvicorn, two workers left running) on a copy of the processed demo (the
    ``processed_demo`` fixture, tests/demo_db.py: 4 runs of 1.2 km at 10 kHz on two lines, reference
    data of line SIM, both lines' geometry, processed once per session and shared with the golden
    identity test; its webhook is deleted here, the browser tests have no receiver), a further run
    file for the upload test and a bad file."""
    from app.simulate.run import simulate_run

    work = tmp_path_factory.mktemp("dashboard")
    upload = work / "upload-run.h5"
    # short (0.3 km, ~14 s): what the upload test watches is the upload's progress and its job finishing
    simulate_run(upload, length_km=0.3, fs=RUN_FS, seed=21, line_seed=LINE_SEED,
                 start_time="2025-01-15T09:30:00+01:00", with_forces=False)
    bad = work / "broken-run.csv"
    bad.write_text("time,Z11,speed\n0.0,1.0,20\n0.0001,oops,20\n")
    url, store = processed_demo.copy_to(work / "service")
    with running_service(work / "service", url, run_store=store) as svc:
        from app.db import auth_crud
        from app.db.session import Database

        db = Database(svc.database_url)
        with db.write() as session:
            auth_crud.create_user(session, USER, PASSWORD, "engineer", password_cost=TEST_PASSWORD_COST)
        db.dispose()
        with svc.client(timeout=120) as client:
            r = client.delete(f"/api/v1/webhooks/{processed_demo.webhook_id}")
            assert r.status_code == 204, r.text
            for job_id in processed_demo.job_ids:
                assert client.get(f"/api/v1/jobs/{job_id}").json()["status"] == "done"
        svc.start_worker()
        svc.start_worker()
        yield Dashboard(service=svc, run_ids=list(processed_demo.run_ids), upload_file=upload, bad_file=bad)


@pytest.fixture(scope="session")
def login_state(browser, dashboard) -> dict:
    """Cookies of a browser session logged in as the engineer (one login for all tests)."""
    ctx = browser.new_context(base_url=dashboard.base_url)
    try:
        r = ctx.request.post("/api/v1/auth/login", data={"username": USER, "password": PASSWORD})
        assert r.status == 200, r.text()
        return ctx.storage_state()
    finally:
        ctx.close()


@pytest.fixture
def context(browser, dashboard, login_state) -> Iterator[object]:
    """THE place where browser contexts are made: logged in as the engineer."""
    ctx = browser.new_context(
        base_url=dashboard.base_url, viewport={"width": 1400, "height": 900}, accept_downloads=True,
        storage_state=login_state,
    )
    ctx.set_default_timeout(60_000)
    try:
        yield ctx
    finally:
        ctx.close()


@dataclass
class PageLog:
    """What a page did: console errors, page errors, failed requests, every request URL."""

    origin: str
    console_errors: list[str] = field(default_factory=list)
    page_errors: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)

    def attach(self, page) -> None:
        page.on("console", lambda m: self.console_errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: self.page_errors.append(str(e)))
        page.on("requestfailed", lambda r: self.failed.append(f"{r.method} {r.url}: {r.failure}"))
        page.on("response", lambda r: self.failed.append(f"{r.request.method} {r.url}: HTTP {r.status}")
                if r.status >= 400 else None)
        page.on("request", lambda r: self.requests.append(r.url))

    def foreign(self) -> list[str]:
        """Requests that did not go to the app's own origin (blob:/data: URLs are local)."""
        own = urlsplit(self.origin)
        out = []
        for url in self.requests:
            parts = urlsplit(url)
            if parts.scheme in ("blob", "data"):
                continue
            if (parts.scheme, parts.netloc) != (own.scheme, own.netloc):
                out.append(url)
        return out

    def assert_clean(self) -> None:
        assert not self.page_errors, f"page errors: {self.page_errors}"
        assert not self.console_errors, f"console errors: {self.console_errors}"
        assert not self.failed, f"failed requests: {self.failed}"


@pytest.fixture
def open_page(context, dashboard):
    """Open a dashboard URL, wait until its script says ready; returns (page, log)."""

    def _open(path: str):
        page = context.new_page()
        log = PageLog(origin=dashboard.base_url)
        log.attach(page)
        page.goto(path)
        page.wait_for_selector("body[data-ready='1']")
        return page, log

    return _open


def save_screenshot(page, name: str) -> Path:
    """Full-page screenshot to ``SCREENSHOTS/<name>.png`` (read them: the walk's record of each page)."""
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    path = SCREENSHOTS / f"{name}.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    page.wait_for_timeout(300)  # let Plotly finish its transitions
    page.screenshot(path=str(path), full_page=True)
    return path
