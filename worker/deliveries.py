"""The webhook delivery loop of a worker process (both worker modes).

Deliveries are queued by the publish step in the transaction that publishes
a run with new condition flags (:func:`app.condition.alerts.enqueue_new_flags`);
this loop, a daemon thread of every worker process, claims the due ones
(:func:`app.db.webhooks.claim_due`), sends each as an HMAC-signed JSON POST
(:mod:`app.core.signing`) through :func:`app.alerts.transport.post` — the
address policy checked on the address connected to, no redirects, one total
timeout, a bounded read of the answer — and records a coarse outcome: 2xx is
delivered, anything else (no answer, timeout, 4xx/5xx, refused by the policy)
is retried with exponential back-off until ``webhook_max_attempts``
(:class:`app.db.webhooks.RetryPolicy`). What the receiver answered is never
stored.

Up to ``webhook_concurrency`` deliveries are in flight at once, at most one per
webhook, each in a thread of a small pool: a receiver that trickles its answer
holds one thread for ``webhook_timeout_s`` at most, and the others keep going.
The loop runs beside the jobs and never in their way.

Request: ``POST <url>`` with the delivery's payload as JSON plus
``delivery_id`` and ``attempt``; headers ``Content-Type: application/json``,
``X-Trackvkf-Event``, ``X-Trackvkf-Delivery`` (the id: deduplicate by it, a
delivery may arrive twice) and ``X-Trackvkf-Signature: t=<unix>,v1=<hex>``
(a second ``v1=`` with the previous secret while a rotation's grace period lasts).
"""

from __future__ import annotations

import json
import logging
import threading
from concurrent.futures import Future, ThreadPoolExecutor, wait

from app.alerts.transport import Attempt, post
from app.core.signing import SIGNATURE_HEADER, signature_header
from app.core.url_policy import AddressPolicy, Resolver
from app.db import webhooks
from app.db.models import utcnow
from app.db.session import Database
from app.settings import Settings
from worker.loops import PeriodicLoop

__all__ = ["DeliveryLoop", "deliver_due", "send_one", "retry_policy", "EVENT_HEADER", "DELIVERY_HEADER"]

log = logging.getLogger(__name__)

EVENT_HEADER = "X-Trackvkf-Event"
DELIVERY_HEADER = "X-Trackvkf-Delivery"


def retry_policy(settings: Settings) -> webhooks.RetryPolicy:
    """The back-off of the settings (``webhook_*``)."""
    return webhooks.RetryPolicy(settings.webhook_max_attempts, settings.webhook_retry_base_s,
                                settings.webhook_retry_max_s)


def _lease_s(settings: Settings) -> float:
    return 2 * settings.webhook_timeout_s + 30


def send_one(db: Database, settings: Settings, d: webhooks.Claimed, *, resolver: Resolver | None = None) -> Attempt:
    """Send one claimed delivery and record its outcome."""
    started = utcnow()
    body = json.dumps({**d.payload, "delivery_id": d.id, "attempt": d.attempts + 1}, separators=(",", ":")).encode()
    headers = {"Content-Type": "application/json", EVENT_HEADER: d.event, DELIVERY_HEADER: str(d.id),
               SIGNATURE_HEADER: signature_header(d.sign_with, body), "User-Agent": "trackvkf-webhooks"}
    attempt = post(d.url, body, headers, policy=AddressPolicy.from_settings(settings),
                   timeout_s=settings.webhook_timeout_s, max_answer_bytes=settings.webhook_max_answer_bytes,
                   resolver=resolver)
    # the attempt is recorded at its start: how long it took is not shown (a timing oracle for ports)
    status = webhooks.finish_attempt(db, d.id, ok=attempt.ok, status_code=attempt.status_code,
                                     error=attempt.summary, policy=retry_policy(settings), now=started)
    if not attempt.ok:
        log.warning("webhook %s delivery %s attempt %d: %s, %s (now %s)", d.webhook_id, d.id, d.attempts + 1,
                    attempt.outcome, attempt.detail, status)
    return attempt


def deliver_due(db: Database, settings: Settings, *, resolver: Resolver | None = None) -> int:
    """Send the deliveries due now (one batch, ``webhook_concurrency`` at once, one per webhook);
    the number attempted. Returns when all of them are done."""
    claimed = webhooks.claim_due(db, limit=settings.webhook_concurrency, lease_s=_lease_s(settings),
                                 one_per_webhook=True)
    if not claimed:
        return 0
    with ThreadPoolExecutor(max_workers=len(claimed), thread_name_prefix="webhook-send") as pool:
        for future in [pool.submit(send_one, db, settings, d, resolver=resolver) for d in claimed]:
            future.result()
    return len(claimed)


class DeliveryLoop(PeriodicLoop):
    """Daemon thread sending due webhook deliveries, ``webhook_concurrency`` at once (one per webhook),
    pausing ``webhook_poll_s`` when none is due or every slot is busy.

    Parameters
    ----------
    settings : Settings
    db : Database
    resolver : callable, optional
        Name resolution of the transport (tests; default: the system resolver).
    """

    def __init__(self, settings: Settings, db: Database, resolver: Resolver | None = None) -> None:
        self.settings, self.db, self.resolver = settings, db, resolver
        self.pool = ThreadPoolExecutor(max_workers=settings.webhook_concurrency, thread_name_prefix="webhook-send")
        self._lock = threading.Lock()
        self._in_flight: dict[Future, int] = {}  # future → webhook id
        self._wake = threading.Event()
        super().__init__("webhook-deliveries", self._step, settings.webhook_poll_s)

    def _step(self) -> bool:
        with self._lock:
            busy = list(self._in_flight.values())
        free = self.settings.webhook_concurrency - len(busy)
        if free <= 0:
            self._wake.wait(self.settings.webhook_poll_s)  # a send ends: look again at once
            self._wake.clear()
            return True
        claimed = webhooks.claim_due(self.db, limit=free, lease_s=_lease_s(self.settings), busy_webhooks=busy,
                                     one_per_webhook=True)
        for d in claimed:
            future = self.pool.submit(send_one, self.db, self.settings, d, resolver=self.resolver)
            with self._lock:
                self._in_flight[future] = d.webhook_id
            future.add_done_callback(self._done)
        return bool(claimed)

    def _done(self, future: Future) -> None:
        with self._lock:
            self._in_flight.pop(future, None)
        exc = future.exception()
        if exc is not None:  # the database was away when recording: the claim expires and it is sent again
            log.warning("webhook delivery: %s", exc)
        self._wake.set()

    def stop(self, timeout: float | None = None) -> None:
        """Stop claiming; wait for the sends in flight (``timeout`` s at most)."""
        self._wake.set()
        super().stop(timeout)
        with self._lock:
            futures = list(self._in_flight)
        wait(futures, timeout=timeout)
        self.pool.shutdown(wait=False, cancel_futures=True)
