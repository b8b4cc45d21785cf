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

A webhook's URL is checked by :func:`app.core.url_policy.check_url` (syntax)
here; where it may point (the SSRF policy) is checked by the API when it is
registered and by the transport at every delivery. A secret is rotated by
:func:`rotate_secret`: the previous secret keeps signing deliveries (a second
signature) until its grace period ends.
"""

from __future__ import annotations

import datetime as dt
import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import and_, func, or_, select, update
from sqlalchemy.orm import Session

from app.core.url_policy import check_url as _check_url_syntax
from app.db.models import DeliveryStatus, Webhook, WebhookDelivery, utcnow
from app.db.session import Database

__all__ = [
    "EVENT_FLAGS",
    "EVENT_PING",
    "EVENT_PLACES",
    "RetryPolicy",
    "Claimed",
    "check_url",
    "new_secret",
    "create_webhook",
    "rotate_secret",
    "signing_secrets",
    "enqueue",
    "claim_due",
    "finish_attempt",
    "list_deliveries",
    "list_webhooks",
    "delivery_counts",
    "delete_webhook",
]

#: Event of new condition flags in a published run.
EVENT_FLAGS = "condition.flags"
#: Event of place alerts (a new place, a tier change, a place back): :mod:`app.places.alerts`.
EVENT_PLACES = "condition.places"
#: Event of a test delivery (``POST /webhooks/{id}/test``).
EVENT_PING = "ping"


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
    sign_with: tuple[str, ...]  # the current secret, and the previous one in its grace period
    event: str
    payload: dict[str, Any]
    attempts: int


def check_url(url: str) -> str:
    """The URL, stripped; ValueError (:class:`app.core.url_policy.UrlError`) unless its syntax
    is acceptable: http(s), a host, a port in 1–65535, no credentials, no spaces or control characters."""
    return _check_url_syntax(url)


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


def rotate_secret(hook: Webhook, secret: str, *, grace_s: float, now: dt.datetime | None = None) -> None:
    """Make ``secret`` the webhook's signing secret; the current one stays valid for ``grace_s`` seconds.

    Deliveries sent within the grace period carry both signatures (new first).
    Rotating again within a grace period drops the oldest secret.
    """
    if len(secret) < 16:
        raise ValueError("secret: at least 16 characters")
    if grace_s < 0:
        raise ValueError(f"grace_s must be >= 0, got {grace_s}")
    now = now or utcnow()
    if secret != hook.secret:
        hook.previous_secret = hook.secret if grace_s > 0 else None
        hook.previous_secret_until = now + dt.timedelta(seconds=grace_s) if grace_s > 0 else None
        hook.secret = secret
    hook.secret_rotated_at = now


def signing_secrets(hook: Webhook, now: dt.datetime | None = None) -> tuple[str, ...]:
    """The secrets a delivery is signed with now: the current one, and the previous one in its grace period."""
    now = now or utcnow()
    if hook.previous_secret and hook.previous_secret_until is not None and hook.previous_secret_until > now:
        return (hook.secret, hook.previous_secret)
    return (hook.secret,)


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


def claim_due(db: Database, *, limit: int = 20, lease_s: float = 60.0, busy_webhooks: Sequence[int] = (),
              one_per_webhook: bool = False, now: dt.datetime | None = None) -> list[Claimed]:
    """Claim up to ``limit`` due deliveries (pending and due, or sending with an expired lease).

    Each is claimed by a guarded update, so two loops never send the same one
    at once; the claim lasts ``lease_s`` seconds.

    Parameters
    ----------
    busy_webhooks : sequence of int
        Webhooks whose deliveries are not claimed now (the caller is sending to them).
    one_per_webhook : bool
        Claim at most one delivery per webhook (the oldest due).
    """
    if limit <= 0:
        return []
    now = now or utcnow()
    out: list[Claimed] = []
    busy = set(busy_webhooks)
    with db.write() as session:
        due = select(WebhookDelivery).where(_due(now))
        if busy:
            due = due.where(WebhookDelivery.webhook_id.not_in(busy))
        if one_per_webhook:
            # the webhooks with something due, longest waiting first, then each one's oldest delivery:
            # a webhook with a long backlog does not keep the others from their turn
            waiting = select(WebhookDelivery.webhook_id).where(_due(now))
            if busy:
                waiting = waiting.where(WebhookDelivery.webhook_id.not_in(busy))
            hook_ids = session.scalars(
                waiting.group_by(WebhookDelivery.webhook_id)
                .order_by(func.min(WebhookDelivery.next_attempt_at), WebhookDelivery.webhook_id).limit(limit)
            ).all()
            candidates = [session.scalars(due.where(WebhookDelivery.webhook_id == h).order_by(
                WebhookDelivery.next_attempt_at, WebhookDelivery.id).limit(1)).first() for h in hook_ids]
        else:
            candidates = list(session.scalars(
                due.order_by(WebhookDelivery.next_attempt_at, WebhookDelivery.id).limit(limit)))
        for d in candidates:
            if d is None or len(out) >= limit:
                continue
            hook = session.get(Webhook, d.webhook_id)
            result = session.execute(
                update(WebhookDelivery).where(WebhookDelivery.id == d.id, _due(now))
                .values(status=DeliveryStatus.SENDING, locked_until=now + dt.timedelta(seconds=lease_s))
            )
            if result.rowcount == 1 and hook is not None:
                out.append(Claimed(d.id, hook.id, hook.url, signing_secrets(hook, now), d.event, dict(d.payload),
                                   d.attempts))
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


def list_webhooks(session: Session) -> list[Webhook]:
    """All webhooks by id."""
    return list(session.scalars(select(Webhook).order_by(Webhook.id)))


def delivery_counts(session: Session, webhook_id: int) -> dict[str, int]:
    """How many deliveries of the webhook are in each status (every status of
    :data:`~app.db.models.DeliveryStatus.ALL`, zero where none)."""
    counts = {s: 0 for s in DeliveryStatus.ALL}
    for status, n in session.execute(select(WebhookDelivery.status, func.count())
                                     .where(WebhookDelivery.webhook_id == webhook_id)
                                     .group_by(WebhookDelivery.status)):
        counts[status] = counts.get(status, 0) + int(n)
    return counts


def delete_webhook(session: Session, webhook_id: int) -> Webhook | None:
    """Delete a webhook with its delivery log; the deleted row, or None when there was none."""
    hook = session.get(Webhook, webhook_id)
    if hook is None:
        return None
    session.query(WebhookDelivery).filter(WebhookDelivery.webhook_id == webhook_id).delete()
    session.delete(hook)
    return hook
