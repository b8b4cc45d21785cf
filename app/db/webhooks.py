"""Webhooks and their delivery log: configuration, the outbox, claims and retries.

Deliveries are an outbox: :func:`enqueue` adds one row per active webhook,
for new condition flags in the transaction that publishes the run
(:mod:`app.condition.alerts`: an alert exists exactly when the flags do), and the workers'
delivery loop (:mod:`worker.deliveries`) sends them apart from the jobs — a
receiver that is down never holds up processing. Claims and outcomes are
guarded conditional updates (a delivery is sent by one loop at a time; a loop
that dies leaves its claim to expire after the lease), so delivery is
at-least-once: receivers deduplicate by the ``X-Trackvkf-Delivery`` id.
Failed attempts are retried with exponential back-off (:class:`RetryPolicy`).
"""

from __future__ import annotations

import datetime as dt
import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

from sqlalchemy import and_, func, or_, select, update
from sqlalchemy.orm import Session

from app.db.models import DeliveryStatus, Webhook, WebhookDelivery, utcnow
from app.db.session import Database

__all__ = [
    "EVENT_FLAGS",
    "EVENT_PING",
    "RetryPolicy",
    "Claimed",
    "check_url",
    "new_secret",
    "create_webhook",
    "enqueue",
    "claim_due",
    "finish_attempt",
    "list_deliveries",
]

#: Event of new condition flags in a published run.
EVENT_FLAGS = "condition.flags"
#: Event of a test delivery (``POST /webhooks/{id}/test``).
EVENT_PING = "ping"
_MAX_URL = 2000


@dataclass(frozen=True)
class RetryPolicy:
    """Back-off of failed deliveries: ``base_s · 2^(attempt − 1)`` seconds, at most ``max_s``,
    until ``max_attempts`` attempts failed."""

    max_attempts: int = 8
    base_s: float = 5.0
    max_s: float = 3600.0

    def delay_s(self, attempts: int) -> float:
        """Seconds before the next attempt after ``attempts`` failed ones."""
        return min(self.base_s * 2.0 ** max(attempts - 1, 0), self.max_s)


@dataclass(frozen=True)
class Claimed:
    """A delivery claimed for sending, with what is needed to send it."""

    id: int
    webhook_id: int
    url: str
    secret: str
    event: str
    payload: dict[str, Any]
    attempts: int


def check_url(url: str) -> str:
    """The URL, stripped; ValueError unless it is an absolute http(s) URL with a host."""
    value = (url or "").strip()
    if len(value) > _MAX_URL:
        raise ValueError(f"at most {_MAX_URL} characters")
    parts = urlsplit(value)
    if parts.scheme not in ("http", "https"):
        raise ValueError(f"must be an http:// or https:// URL, got {value[:80]!r}")
    if not parts.hostname:
        raise ValueError("has no host")
    return value


def new_secret() -> str:
    """A random signing secret (``whsec_`` + 43 URL-safe characters)."""
    return "whsec_" + secrets.token_urlsafe(32)


def create_webhook(session: Session, url: str, *, description: str | None = None, secret: str | None = None,
                   created_by: str | None = None) -> Webhook:
    """A new active webhook (URL checked with :func:`check_url`; a secret made when none is given)."""
    hook = Webhook(url=check_url(url), secret=secret or new_secret(), description=description, active=True,
                   created_by=created_by, created_at=utcnow())
    session.add(hook)
    session.flush()
    return hook


def enqueue(session: Session, event: str, payload: dict[str, Any], *, run_id: int | None = None,
            webhook_ids: Sequence[int] | None = None) -> list[int]:
    """One pending delivery per active webhook (or per webhook of ``webhook_ids``); their ids."""
    stmt = select(Webhook.id)
    stmt = stmt.where(Webhook.id.in_(list(webhook_ids))) if webhook_ids is not None else stmt.where(
        Webhook.active.is_(True))
    ids = []
    now = utcnow()
    for hook_id in session.scalars(stmt.order_by(Webhook.id)):
        row = WebhookDelivery(webhook_id=hook_id, event=event, run_id=run_id, payload=payload,
                              status=DeliveryStatus.PENDING, attempts=0, next_attempt_at=now, created_at=now)
        session.add(row)
        session.flush()
        ids.append(row.id)
    return ids


def _due(now: dt.datetime):
    return or_(
        and_(WebhookDelivery.status == DeliveryStatus.PENDING, WebhookDelivery.next_attempt_at <= now),
        and_(WebhookDelivery.status == DeliveryStatus.SENDING, WebhookDelivery.locked_until < now),
    )


def claim_due(db: Database, *, limit: int = 20, lease_s: float = 60.0,
              now: dt.datetime | None = None) -> list[Claimed]:
    """Claim up to ``limit`` due deliveries (pending and due, or sending with an expired lease).

    Each is claimed by a guarded update, so two loops never send the same one
    at once; the claim lasts ``lease_s`` seconds.
    """
    now = now or utcnow()
    out = []
    with db.write() as session:
        rows = session.execute(
            select(WebhookDelivery, Webhook).join(Webhook, Webhook.id == WebhookDelivery.webhook_id)
            .where(_due(now)).order_by(WebhookDelivery.next_attempt_at, WebhookDelivery.id).limit(limit)
        ).all()
        for d, hook in rows:
            result = session.execute(
                update(WebhookDelivery).where(WebhookDelivery.id == d.id, _due(now))
                .values(status=DeliveryStatus.SENDING, locked_until=now + dt.timedelta(seconds=lease_s))
            )
            if result.rowcount == 1:
                out.append(Claimed(d.id, hook.id, hook.url, hook.secret, d.event, dict(d.payload), d.attempts))
    return out


def finish_attempt(db: Database, delivery_id: int, *, ok: bool, status_code: int | None = None,
                   error: str | None = None, policy: RetryPolicy = RetryPolicy(),
                   now: dt.datetime | None = None) -> str | None:
    """Record an attempt of a claimed delivery; its new status (None if no longer claimed)."""
    now = now or utcnow()
    with db.write() as session:
        d = session.get(WebhookDelivery, delivery_id)
        if d is None or d.status != DeliveryStatus.SENDING:
            return None
        attempts = d.attempts + 1
        if ok:
            status, next_at, delivered = DeliveryStatus.DELIVERED, d.next_attempt_at, now
        elif attempts >= policy.max_attempts:
            status, next_at, delivered = DeliveryStatus.FAILED, d.next_attempt_at, None
        else:
            status = DeliveryStatus.PENDING
            next_at, delivered = now + dt.timedelta(seconds=policy.delay_s(attempts)), None
        result = session.execute(
            update(WebhookDelivery).where(WebhookDelivery.id == delivery_id,
                                          WebhookDelivery.status == DeliveryStatus.SENDING,
                                          WebhookDelivery.attempts == d.attempts)
            .values(status=status, attempts=attempts, next_attempt_at=next_at, locked_until=None,
                    last_attempt_at=now, last_status_code=status_code,
                    last_error=(error or "")[:2000] or None, delivered_at=delivered)
        )
        return status if result.rowcount == 1 else None


def list_deliveries(session: Session, *, webhook_id: int | None = None, status: str | None = None,
                    limit: int = 100, offset: int = 0) -> tuple[list[WebhookDelivery], int]:
    """The delivery log, newest first, and how many match."""
    conds = []
    if webhook_id is not None:
        conds.append(WebhookDelivery.webhook_id == webhook_id)
    if status is not None:
        conds.append(WebhookDelivery.status == status)
    total = session.scalar(select(func.count()).select_from(WebhookDelivery).where(*conds)) or 0
    rows = session.scalars(select(WebhookDelivery).where(*conds).order_by(WebhookDelivery.id.desc())
                           .limit(limit).offset(offset))
    return list(rows), int(total)
