"""Alerts: webhooks called when a published run has new flags — HMAC-signed, retried with
back-off, logged — against a real local HTTP receiver, also one that is down and comes back."""

from __future__ import annotations

import datetime as dt
import json
import socket
import threading
import time
from dataclasses import replace
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from app.core.signing import SIGNATURE_HEADER, verify
from app.db import webhooks
from app.db.models import DeliveryStatus, WebhookDelivery
from app.db.session import Database
from app.places.config import DEFAULT_PLACES_CONFIG
from app.simulate.fleet import FleetNoise, FleetPlan, FleetSimulator, PlantedStep
from app.simulate.track import generate_line
from tests.condition.support import DAY0, publish_tracks
from worker.deliveries import DELIVERY_HEADER, EVENT_HEADER, DeliveryLoop, deliver_due

LINE = generate_line(12_000.0, 15_000.0, seed=7)
QUIET = FleetNoise(segment_sd=0.02, run_sd=0.01, speed_spread=0.03, speed_wobble=0.02)


class Receiver:
    """A tiny HTTP server on a fixed local port that records POSTs; stop() takes it down
    (connections refused), start() brings it back on the same port."""

    def __init__(self, status: int = 200) -> None:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        self.status = status
        self.requests: list[tuple[dict[str, str], bytes]] = []
        self._server: ThreadingHTTPServer | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/hook"

    def start(self) -> None:
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 - http.server's name
                body = self.rfile.read(int(self.headers["Content-Length"]))
                receiver.requests.append((dict(self.headers), body))
                self.send_response(receiver.status)
                self.end_headers()
                self.wfile.write(b"ok")

            def log_message(self, *args: object) -> None:
                pass

        self._server = ThreadingHTTPServer(("127.0.0.1", self.port), Handler)
        threading.Thread(target=self._server.serve_forever, daemon=True).start()

    def stop(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None


@pytest.fixture
def receiver():
    r = Receiver()
    yield r
    r.stop()


@pytest.fixture
def admin(make_client):
    """An admin client; deliveries back off as configured by default (5 s doubling: the tests move the
    service's clock on instead of waiting)."""
    return make_client(webhook_timeout_s=2.0, webhook_max_attempts=3,
                       webhook_allowed_networks="127.0.0.1/32")  # the local receiver: allow-listed


#: these tests are about the flags' alerts: the places' alerts (new places of the generated line on its
#: first runs) are tested in tests/places
FLAG_ALERTS_ONLY = replace(DEFAULT_PLACES_CONFIG, alerts=False)


def _step_history(db: Database, n: int = 11) -> int:
    """Publish ``n`` daily runs; a 20 % step over 20 m from the last one on. Returns its run id."""
    sim = FleetSimulator(LINE, FleetPlan(steps=(PlantedStep(13_400.0, 13_420.0, day=n - 1, factor=1.2),)), QUIET,
                         grid_m=0.25)
    import numpy as np

    run_id = None
    for i in range(n):
        _, tracks = sim.run(float(i), np.random.default_rng([5, i]))
        run_id, _, summary = publish_tracks(db, tracks, DAY0 + dt.timedelta(days=i), places=FLAG_ALERTS_ONLY)
    assert summary["new_flag_ids"], summary
    return run_id


def test_webhook_urls_must_be_http(admin):
    for url in ("ftp://example.org/x", "file:///etc/passwd", "example.org/hook", "http://", "javascript:alert(1)"):
        r = admin.post("/api/v1/webhooks", json={"url": url})
        assert r.status_code == 422, (url, r.text)
        assert r.json()["field"] == "url"
    assert admin.get("/api/v1/webhooks").json()["items"] == []
    assert admin.patch("/api/v1/webhooks/5", json={"active": False}).status_code == 404


def test_only_admins_manage_webhooks(make_client):
    engineer = make_client(role="engineer")
    assert engineer.get("/api/v1/webhooks").status_code == 403
    assert engineer.post("/api/v1/webhooks", json={"url": "http://127.0.0.1:9/x"}).status_code == 403


def test_new_flags_are_delivered_signed_to_a_receiver_that_was_down(admin, receiver, clock):
    created = admin.post("/api/v1/webhooks", json={"url": receiver.url, "description": "asset system"})
    assert created.status_code == 201, created.text
    hook = created.json()
    assert hook["secret"].startswith("whsec_") and hook["active"]
    assert "secret" not in admin.get("/api/v1/webhooks").json()["items"][0]
    db = Database(admin.settings.database_url)
    try:
        t0 = time.perf_counter()
        run_id = _step_history(db)  # the receiver is down all the while: publishing is not held up
        publish_s = time.perf_counter() - t0
        with db.read() as s:
            (d,) = s.query(WebhookDelivery).all()
        assert (d.status, d.run_id, d.event) == (DeliveryStatus.PENDING, run_id, webhooks.EVENT_FLAGS)
        assert deliver_due(db, admin.settings) == 1  # refused: the receiver is down
        log = admin.get("/api/v1/webhooks/deliveries").json()
        (item,) = log["items"]
        assert item["status"] == "pending" and item["attempts"] == 1 and item["last_status_code"] is None
        assert item["last_error"].startswith("no answer")
        assert deliver_due(db, admin.settings) == 0  # backing off: not due yet
        receiver.start()  # the receiver comes back
        clock.advance(admin.settings.webhook_retry_base_s - 0.5)
        assert deliver_due(db, admin.settings) == 0  # still backing off
        clock.advance(0.6)
        assert deliver_due(db, admin.settings) == 1
        item = admin.get("/api/v1/webhooks/deliveries", params={"status": "delivered"}).json()["items"][0]
        assert item["attempts"] == 2 and item["last_status_code"] == 200 and item["delivered_at"]
        (headers, body), = receiver.requests
        assert verify(hook["secret"], headers[SIGNATURE_HEADER], body)
        assert not verify(hook["secret"], headers[SIGNATURE_HEADER], body + b" ")
        assert not verify("whsec_other", headers[SIGNATURE_HEADER], body)
        assert headers[EVENT_HEADER] == "condition.flags" and headers[DELIVERY_HEADER] == str(item["id"])
        payload = json.loads(body)
        assert payload["run_id"] == run_id and payload["line_id"] == "L1" and payload["attempt"] == 2
        assert payload["n_flags"] == len(payload["flags"]) > 0
        assert any(f["kind"] == "step" and 13.39 <= f["km_from"] < 13.42 and f["direction"] == "up"
                   for f in payload["flags"])
        feed = admin.get("/api/v1/condition/flags", params={"since": payload["feed_since"], "new_only": True})
        assert {f["id"] for f in payload["flags"]} <= {f["id"] for f in feed.json()["items"]}
        assert admin.get("/api/v1/webhooks").json()["items"][0]["pending"] == 0
    finally:
        db.dispose()
    assert publish_s < 120


def test_a_delivery_is_given_up_after_the_last_attempt(admin, receiver, clock):
    receiver.status = 500
    receiver.start()
    hook = admin.post("/api/v1/webhooks", json={"url": receiver.url}).json()
    assert admin.post(f"/api/v1/webhooks/{hook['id']}/test").status_code == 202
    db = Database(admin.settings.database_url)
    try:
        for attempt in range(1, 4):
            assert deliver_due(db, admin.settings) == 1
            clock.advance(admin.settings.webhook_retry_base_s * 2 ** (attempt - 1) + 0.1)  # its back-off
        assert deliver_due(db, admin.settings) == 0
    finally:
        db.dispose()
    (item,) = admin.get("/api/v1/webhooks/deliveries", params={"webhook_id": hook["id"]}).json()["items"]
    assert item["status"] == "failed" and item["attempts"] == 3 and item["last_status_code"] == 500
    assert len(receiver.requests) == 3
    assert admin.get("/api/v1/webhooks").json()["items"][0]["failed"] == 1
    assert admin.get("/api/v1/webhooks/deliveries", params={"status": "nope"}).status_code == 422


def test_the_delivery_loop_sends_in_the_background_and_inactive_hooks_get_nothing(admin, receiver):
    receiver.start()
    on = admin.post("/api/v1/webhooks", json={"url": receiver.url}).json()
    off = admin.post("/api/v1/webhooks", json={"url": receiver.url + "?off"}).json()
    assert admin.patch(f"/api/v1/webhooks/{off['id']}", json={"active": False}).json()["active"] is False
    db = Database(admin.settings.database_url)
    loop = DeliveryLoop(admin.settings, db)
    loop.start()
    try:
        with db.write() as s:
            assert len(webhooks.enqueue(s, webhooks.EVENT_PING, {"event": "ping"})) == 1  # the active one only
        deadline = time.monotonic() + 20
        while not receiver.requests and time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        loop.stop(timeout=10)
        db.dispose()
    assert len(receiver.requests) == 1 and not loop.is_alive()
    assert admin.delete(f"/api/v1/webhooks/{on['id']}").status_code == 204
    assert [h["id"] for h in admin.get("/api/v1/webhooks").json()["items"]] == [off["id"]]
    audit = admin.get("/api/v1/audit", params={"action": "webhook.create"}).json()
    assert len(audit["items"]) == 2
