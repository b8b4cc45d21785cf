"""The webhook delivery loop of a worker process (both worker modes).

Deliveries are queued by the publish step in the transaction that publishes
a run with new condition flags (:func:`app.condition.alerts.enqueue_new_flags`);
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

import httpx

from app.core.config import Settings
from app.core.signing import SIGNATURE_HEADER, signature_header
from app.db import webhooks
from app.db.session import Database
from worker.loops import PeriodicLoop

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


class DeliveryLoop(PeriodicLoop):
    """Daemon thread sending due webhook deliveries, pausing ``webhook_poll_s`` when none is due.

    Parameters
    ----------
    settings : Settings
    db : Database
    """

    def __init__(self, settings: Settings, db: Database) -> None:
        self.client = httpx.Client(follow_redirects=False)
        super().__init__("webhook-deliveries", lambda: deliver_due(db, settings, self.client) > 0,
                         settings.webhook_poll_s)

    def run(self) -> None:
        try:
            super().run()
        finally:
            self.client.close()
