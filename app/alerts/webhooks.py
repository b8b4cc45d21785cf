"""Webhooks, administered by admins: receivers registered, changed (a secret rotated), deleted,
pinged, and the delivery log, each change with its audit entry in one transaction.

A receiver's URL must be http(s) without credentials and resolve to allowed addresses only
(:mod:`app.core.url_policy`, ``TRACKVKF_WEBHOOK_ALLOWED_NETWORKS``): 422 naming ``url``. Answers
are the JSON the API returns (URLs with credential-like query values masked, never a secret but
the one a registration makes).
"""

from __future__ import annotations

from typing import Any

from app.audit import record
from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.core.jsonable import iso_time
from app.core.security import Actor
from app.core.url_policy import AddressPolicy, UrlError, redact_url, resolve
from app.db import webhooks as q
from app.db.models import DeliveryStatus, Webhook, WebhookDelivery
from app.db.session import Database
from app.settings import Settings

__all__ = ["register", "webhook_list", "change", "remove", "ping", "delivery_log"]


def _checked_url(value: str, settings: Settings) -> str:
    """The URL if its syntax is acceptable and its host resolves to allowed addresses only (422 naming url)."""
    try:
        url = q.check_url(value)
        resolve(url, AddressPolicy.from_settings(settings))
    except UrlError as exc:
        raise ApiError(422, "url", exc.args[0] if exc.args and isinstance(exc.args[0], str) else str(exc)) from None
    return url


def _answer(session, hook: Webhook) -> dict[str, Any]:
    counts = q.delivery_counts(session, hook.id)
    grace = q.signing_secrets(hook)
    return {"id": hook.id, "url": redact_url(hook.url), "description": hook.description, "active": hook.active,
            "created_by": hook.created_by, "created_at": iso_time(hook.created_at),
            "pending": counts[DeliveryStatus.PENDING] + counts[DeliveryStatus.SENDING],
            "failed": counts[DeliveryStatus.FAILED], "secret_rotated_at": iso_time(hook.secret_rotated_at),
            "previous_secret_valid_until": iso_time(hook.previous_secret_until) if len(grace) > 1 else None}


def _delivery(d: WebhookDelivery) -> dict[str, Any]:
    return {"id": d.id, "webhook_id": d.webhook_id, "event": d.event, "run_id": d.run_id, "status": d.status,
            "attempts": d.attempts, "next_attempt_at": iso_time(d.next_attempt_at),
            "last_attempt_at": iso_time(d.last_attempt_at), "last_status_code": d.last_status_code,
            "last_error": d.last_error, "created_at": iso_time(d.created_at), "delivered_at": iso_time(d.delivered_at),
            "n_flags": (d.payload or {}).get("n_flags")}


def register(db: Database, settings: Settings, actor: Actor, url: str, *, description: str | None = None,
             secret: str | None = None) -> dict[str, Any]:
    """Register a receiver (audited ``webhook.create``): the webhook with its signing secret
    (a random one unless given), answered this once.

    Raises
    ------
    ApiError
        422 naming ``url`` (syntax, credentials, or addresses the SSRF policy refuses).
    """
    url = _checked_url(url, settings)
    with db.write() as session:
        hook = q.create_webhook(session, url, description=description, secret=secret, created_by=actor.name)
        record(session, actor, "webhook.create", target=hook.id, detail={"url": redact_url(url)})
        return {**_answer(session, hook), "secret": hook.secret}


def webhook_list(db: Database) -> list[dict[str, Any]]:
    """Every webhook by id, with its pending and failed deliveries."""
    with db.read() as session:
        return [_answer(session, h) for h in q.list_webhooks(session)]


def change(db: Database, settings: Settings, actor: Actor, webhook_id: int, changes: dict[str, Any]) -> dict[str, Any]:
    """Change a webhook's ``url``, ``description`` or ``active`` flag, or rotate its ``secret`` (the
    previous one keeps signing for ``TRACKVKF_WEBHOOK_SECRET_GRACE_S``); audited ``webhook.update``
    with what changed (never a secret).

    Raises
    ------
    ApiError
        404 naming ``webhook``; 422 naming ``url``.
    """
    changed = dict(changes)
    url = _checked_url(changed["url"], settings) if "url" in changed else None
    with db.write() as session:
        hook = session.get(Webhook, webhook_id)
        if hook is None:
            raise not_found("webhook", webhook_id)
        if url is not None:
            hook.url = url
            changed["url"] = redact_url(url)
        if "description" in changed:
            hook.description = changed["description"]
        if "active" in changed:
            hook.active = changed["active"]
        if "secret" in changed:
            q.rotate_secret(hook, changed["secret"], grace_s=settings.webhook_secret_grace_s)
            changed["secret"] = "rotated"  # never the secret itself
        record(session, actor, "webhook.update", target=webhook_id, detail=changed)
        return _answer(session, hook)


def remove(db: Database, actor: Actor, webhook_id: int) -> None:
    """Delete a webhook and its delivery log (audited ``webhook.delete``); 404 naming ``webhook``."""
    with db.write() as session:
        hook = q.delete_webhook(session, webhook_id)
        if hook is None:
            raise not_found("webhook", webhook_id)
        record(session, actor, "webhook.delete", target=webhook_id, detail={"url": redact_url(hook.url)})


def ping(db: Database, webhook_id: int) -> dict[str, Any]:
    """Queue a ``ping`` delivery to the webhook (sent by the workers' delivery loop); 404 naming ``webhook``."""
    with db.write() as session:
        if session.get(Webhook, webhook_id) is None:
            raise not_found("webhook", webhook_id)
        (delivery_id,) = q.enqueue(session, q.EVENT_PING, {"event": q.EVENT_PING}, webhook_ids=[webhook_id])
        return _delivery(session.get(WebhookDelivery, delivery_id))


def delivery_log(db: Database, *, webhook_id: int | None = None, status: str | None = None, limit: int = 100,
                 offset: int = 0) -> dict[str, Any]:
    """The delivery log, newest first: ``total`` and ``items``; 422 naming ``status`` for an unknown one."""
    if status is not None and status not in DeliveryStatus.ALL:
        raise ApiError(422, "status", _("must be one of {choices}, got {status}", choices=', '.join(DeliveryStatus.ALL), status=repr(status)))
    with db.read() as session:
        rows, total = q.list_deliveries(session, webhook_id=webhook_id, status=status, limit=limit, offset=offset)
        return {"total": total, "items": [_delivery(d) for d in rows]}
