"""The webhook delivery loop of a worker process (both worker modes).

Deliveries are queued by the publish step in the transaction that publishes
a run with new condition flags (:func:`app.db.webhooks.enqueue_condition_flags`);
this loop, a daemon thread of every worker process, claims the due ones
(:func:`app.db.webhooks.claim_due`), sends each as an HMAC-signed JSON POST
(:mod:`app.core.signing`) and records the outcome: 2xx is delivered, anything
else (refused connection, timeout, 4xx/5xx) is retried with exponential
back-off until ``webhook_max_attempts`` (:class:`app.db.webhooks.RetryPolicy`).
It runs beside the jobs and never in their way: a receiver that is down costs
this thread a timeout, not a job.

Request: ``POST <url>`` with the delivery's payload as JSON plus
``delivery_id`` and ``attempt``; headers ``Content-Type: application/json``,
``X-Trackvkf-Event``, ``X-Trackvkf-Delivery`` (the id: deduplicate by it, a
delivery may arrive twice) and ``X-Trackvkf-Signature: t=<unix>,v1=<hex>``.
"""

from __future__ import annotations

import json
import logging
import threading

import httpx

from app.core.config import Settings
from app.core.signing import SIGNATURE_HEADER, signature_header
from app.db import webhooks
from app.db.session import Database

__all__ = ["DeliveryLoop", "deliver_due", "retry_policy", "EVENT_HEADER", "DELIVERY_HEADER"]

log = logging.getLogger(__name__)

EVENT_HEADER = "X-Trackvkf-Event"
DELIVERY_HEADER = "X-Trackvkf-Delivery"
_BATCH = 20


def retry_policy(settings: Settings) -> webhooks.RetryPolicy:
    """The back-off of the settings (``webhook_*``)."""
    return webhooks.RetryPolicy(settings.webhook_max_attempts, settings.webhook_retry_base_s,
                                settings.webhook_retry_max_s)


def _send(client: httpx.Client, d: webhooks.Claimed, timeout_s: float) -> tuple[bool, int | None, str | None]:
    body = json.dumps({**d.payload, "delivery_id": d.id, "attempt": d.attempts + 1}, separators=(",", ":")).encode()
    headers = {"Content-Type": "application/json", EVENT_HEADER: d.event, DELIVERY_HEADER: str(d.id),
               SIGNATURE_HEADER: signature_header(d.secret, body), "User-Agent": "trackvkf-webhooks"}
    try:
        r = client.post(d.url, content=body, headers=headers, timeout=timeout_s)
    except httpx.HTTPError as exc:
        return False, None, f"{type(exc).__name__}: {exc}"
    if 200 <= r.status_code < 300:
        return True, r.status_code, None
    return False, r.status_code, f"HTTP {r.status_code}: {r.text[:300]}"


def deliver_due(db: Database, settings: Settings, client: httpx.Client | None = None) -> int:
    """Send the deliveries due now (one batch); the number attempted."""
    claimed = webhooks.claim_due(db, limit=_BATCH, lease_s=2 * settings.webhook_timeout_s + 30)
    if not claimed:
        return 0
    own = client is None
    client = client or httpx.Client(follow_redirects=False)
    policy = retry_policy(settings)
    try:
        for d in claimed:
            ok, code, error = _send(client, d, settings.webhook_timeout_s)
            status = webhooks.finish_attempt(db, d.id, ok=ok, status_code=code, error=error, policy=policy)
            if not ok:
                log.warning("webhook %s delivery %s attempt %d: %s (now %s)", d.webhook_id, d.id, d.attempts + 1,
                            error, status)
    finally:
        if own:
            client.close()
    return len(claimed)


class DeliveryLoop(threading.Thread):
    """Daemon thread sending due webhook deliveries every ``webhook_poll_s`` until :meth:`stop`.

    Parameters
    ----------
    settings : Settings
    db : Database, optional
        Created from the settings if omitted (and disposed at the end).
    """

    def __init__(self, settings: Settings, db: Database | None = None) -> None:
        super().__init__(name="webhook-deliveries", daemon=True)
        self.settings = settings
        self._own_db = db is None
        self.db = db or Database(settings.database_url)
        self._stop_event = threading.Event()

    def stop(self, timeout: float | None = None) -> None:
        """Ask the loop to end and wait for it (``timeout`` s at most)."""
        self._stop_event.set()
        if self.is_alive():
            self.join(timeout)

    def run(self) -> None:
        with httpx.Client(follow_redirects=False) as client:
            while not self._stop_event.is_set():
                try:
                    busy = deliver_due(self.db, self.settings, client)
                except Exception as exc:  # noqa: BLE001 - database away: try again later
                    log.warning("webhook deliveries: %s", exc)
                    busy = 0
                if not busy:
                    self._stop_event.wait(self.settings.webhook_poll_s)
        if self._own_db:
            self.db.dispose()
