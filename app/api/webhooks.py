"""Webhooks (admin): receivers of alerts when a published run has new condition flags, and their
delivery log.

``POST /webhooks`` registers a receiver and answers its signing secret once; the URL must be
http(s) without credentials, and its host must resolve to public addresses only (or to the
allow-listed networks of ``TRACKVKF_WEBHOOK_ALLOWED_NETWORKS``): 422 naming ``url`` otherwise
(docs/security.md, "Webhooks: SSRF policy"). ``GET /webhooks`` (URLs shown with credentials
masked), ``PATCH``/``DELETE /webhooks/{id}`` (``PATCH {"secret": ...}`` rotates the secret: the
previous one keeps signing for ``TRACKVKF_WEBHOOK_SECRET_GRACE_S``); ``POST /webhooks/{id}/test``
queues a ``ping``; ``GET /webhooks/deliveries`` is the log (coarse outcomes only: the receiver's
answer is never kept). The request format and how to verify a signature: docs/condition.md ("Alerts").
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Path, Query, Response, status
from pydantic import BaseModel, Field

from app.api.deps import AdminActor, DbDep, PageOffset, SettingsDep, check_page_size, require_role
from app.api.errors import ApiError, not_found
from app.audit import record
from app.core.jsonable import iso_time
from app.core.url_policy import AddressPolicy, UrlError, redact_url, resolve
from app.db import webhooks
from app.db.models import DeliveryStatus, Webhook, WebhookDelivery

__all__ = ["router"]

router = APIRouter(prefix="/webhooks", tags=["webhooks"], dependencies=[Depends(require_role("admin"))])

WebhookId = Annotated[int, Path(ge=1, le=2**31 - 1, description="Webhook id")]


class WebhookIn(BaseModel):
    url: str = Field(max_length=2000, description="http:// or https:// URL receiving the POSTs")
    description: str | None = Field(default=None, max_length=500)
    secret: str | None = Field(default=None, min_length=16, max_length=128,
                               description="signing secret (default: a random one, answered once)")


class WebhookPatch(BaseModel):
    url: str | None = Field(default=None, max_length=2000)
    description: str | None = Field(default=None, max_length=500)
    active: bool | None = None
    secret: str | None = Field(default=None, min_length=16, max_length=128,
                               description="a new signing secret: rotates it (the previous one keeps signing "
                                           "deliveries, as a second signature, for TRACKVKF_WEBHOOK_SECRET_GRACE_S)")


class WebhookOut(BaseModel):
    id: int
    url: str = Field(description="the receiver's URL, with the values of credential-like query parameters masked")
    description: str | None
    active: bool
    created_by: str | None
    created_at: str
    pending: int = Field(description="deliveries waiting to be sent")
    failed: int = Field(description="deliveries given up")
    secret_rotated_at: str | None = Field(default=None, description="when the secret was last rotated")
    previous_secret_valid_until: str | None = Field(
        default=None, description="deliveries carry a signature with the previous secret too until then")


class WebhookCreated(WebhookOut):
    secret: str = Field(description="the signing secret: shown only now")


class WebhookList(BaseModel):
    items: list[WebhookOut]


class DeliveryOut(BaseModel):
    id: int
    webhook_id: int
    event: str
    run_id: int | None
    status: str
    attempts: int
    next_attempt_at: str | None
    last_attempt_at: str | None
    last_status_code: int | None
    last_error: str | None = Field(description="coarse outcome of the last failed attempt: HTTP <status>, "
                                               "no answer, or refused by the SSRF policy")
    created_at: str
    delivered_at: str | None
    n_flags: int | None


class DeliveryList(BaseModel):
    total: int
    items: list[DeliveryOut]


def _url(value: str, settings) -> str:
    """The URL if its syntax is acceptable and its host resolves to allowed addresses only (422 naming url)."""
    try:
        url = webhooks.check_url(value)
        resolve(url, AddressPolicy.from_settings(settings))
    except UrlError as exc:
        raise ApiError(422, "url", str(exc)) from None
    return url


def _out(session, hook: Webhook) -> dict:
    counts = {s: 0 for s in DeliveryStatus.ALL}
    for d in session.query(WebhookDelivery.status).filter(WebhookDelivery.webhook_id == hook.id):
        counts[d.status] = counts.get(d.status, 0) + 1
    grace = webhooks.signing_secrets(hook)
    return {"id": hook.id, "url": redact_url(hook.url), "description": hook.description, "active": hook.active,
            "created_by": hook.created_by, "created_at": iso_time(hook.created_at),
            "pending": counts[DeliveryStatus.PENDING] + counts[DeliveryStatus.SENDING],
            "failed": counts[DeliveryStatus.FAILED], "secret_rotated_at": iso_time(hook.secret_rotated_at),
            "previous_secret_valid_until": iso_time(hook.previous_secret_until) if len(grace) > 1 else None}


@router.post("", response_model=WebhookCreated, status_code=201, summary="Register a webhook (admin)")
def create(body: WebhookIn, db: DbDep, actor: AdminActor, settings: SettingsDep) -> dict:
    url = _url(body.url, settings)
    with db.write() as session:
        hook = webhooks.create_webhook(session, url, description=body.description, secret=body.secret,
                                       created_by=actor.name)
        record(session, actor, "webhook.create", target=hook.id, detail={"url": redact_url(url)})
        return {**_out(session, hook), "secret": hook.secret}


@router.get("", response_model=WebhookList, summary="List webhooks (admin)")
def list_hooks(db: DbDep) -> dict:
    with db.read() as session:
        return {"items": [_out(session, h) for h in session.query(Webhook).order_by(Webhook.id)]}


@router.patch("/{webhook_id}", response_model=WebhookOut, summary="Change a webhook (admin)")
def change(webhook_id: WebhookId, body: WebhookPatch, db: DbDep, actor: AdminActor,
           settings: SettingsDep) -> dict:
    """Change a webhook's URL, description or active flag, or rotate its secret (``secret``)."""
    changed = body.model_dump(exclude_none=True)
    url = _url(changed["url"], settings) if "url" in changed else None
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
            webhooks.rotate_secret(hook, changed["secret"], grace_s=settings.webhook_secret_grace_s)
            changed["secret"] = "rotated"  # never the secret itself
        record(session, actor, "webhook.update", target=webhook_id, detail=changed)
        return _out(session, hook)


@router.delete("/{webhook_id}", status_code=status.HTTP_204_NO_CONTENT, summary="Delete a webhook (admin)")
def delete(webhook_id: WebhookId, db: DbDep, actor: AdminActor) -> Response:
    with db.write() as session:
        hook = session.get(Webhook, webhook_id)
        if hook is None:
            raise not_found("webhook", webhook_id)
        session.query(WebhookDelivery).filter(WebhookDelivery.webhook_id == webhook_id).delete()
        session.delete(hook)
        record(session, actor, "webhook.delete", target=webhook_id, detail={"url": redact_url(hook.url)})
    return Response(status_code=204)


@router.post("/{webhook_id}/test", response_model=DeliveryOut, status_code=202, summary="Queue a ping (admin)")
def test(webhook_id: WebhookId, db: DbDep) -> dict:
    """Queue a ``ping`` delivery to the webhook (sent by the workers' delivery loop)."""
    with db.write() as session:
        if session.get(Webhook, webhook_id) is None:
            raise not_found("webhook", webhook_id)
        (delivery_id,) = webhooks.enqueue(session, webhooks.EVENT_PING, {"event": webhooks.EVENT_PING},
                                          webhook_ids=[webhook_id])
        return _delivery_out(session.get(WebhookDelivery, delivery_id))


def _delivery_out(d: WebhookDelivery) -> dict:
    return {"id": d.id, "webhook_id": d.webhook_id, "event": d.event, "run_id": d.run_id, "status": d.status,
            "attempts": d.attempts, "next_attempt_at": iso_time(d.next_attempt_at),
            "last_attempt_at": iso_time(d.last_attempt_at), "last_status_code": d.last_status_code,
            "last_error": d.last_error, "created_at": iso_time(d.created_at), "delivered_at": iso_time(d.delivered_at),
            "n_flags": (d.payload or {}).get("n_flags")}


@router.get("/deliveries", response_model=DeliveryList, summary="The delivery log, newest first (admin)")
def deliveries(db: DbDep, settings: SettingsDep,
               webhook_id: Annotated[int | None, Query(ge=1, le=2**31 - 1)] = None,
               status_: Annotated[str | None, Query(alias="status", description="pending, sending, delivered, failed")] = None,
               limit: Annotated[int, Query(ge=1)] = 100, offset: PageOffset = 0) -> dict:
    check_page_size(limit, settings)
    if status_ is not None and status_ not in DeliveryStatus.ALL:
        raise ApiError(422, "status", f"must be one of {', '.join(DeliveryStatus.ALL)}, got {status_!r}")
    with db.read() as session:
        rows, total = webhooks.list_deliveries(session, webhook_id=webhook_id, status=status_, limit=limit,
                                               offset=offset)
        return {"total": total, "items": [_delivery_out(d) for d in rows]}
