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

from app.alerts import webhooks as service
from app.api.deps import AdminActor, DbDep, PageOffset, SettingsDep, check_page_size, require_role
from app.api.schemas.text import Text
from app.core.ids import MAX_ID

__all__ = ["router"]

router = APIRouter(prefix="/webhooks", tags=["webhooks"], dependencies=[Depends(require_role("admin"))])

WebhookId = Annotated[int, Path(ge=1, le=MAX_ID, description="Webhook id")]


class WebhookIn(BaseModel):
    url: Text = Field(max_length=2000, description="http:// or https:// URL receiving the POSTs")
    description: Text | None = Field(default=None, max_length=500)
    secret: Text | None = Field(default=None, min_length=16, max_length=128,
                               description="signing secret (default: a random one, answered once)")


class WebhookPatch(BaseModel):
    url: Text | None = Field(default=None, max_length=2000)
    description: Text | None = Field(default=None, max_length=500)
    active: bool | None = None
    secret: Text | None = Field(default=None, min_length=16, max_length=128,
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


@router.post("", response_model=WebhookCreated, status_code=201, summary="Register a webhook (admin)")
def create(body: WebhookIn, db: DbDep, actor: AdminActor, settings: SettingsDep) -> dict:
    return service.register(db, settings, actor, body.url, description=body.description, secret=body.secret)


@router.get("", response_model=WebhookList, summary="List webhooks (admin)")
def list_hooks(db: DbDep) -> dict:
    return {"items": service.webhook_list(db)}


@router.patch("/{webhook_id}", response_model=WebhookOut, summary="Change a webhook (admin)")
def change(webhook_id: WebhookId, body: WebhookPatch, db: DbDep, actor: AdminActor,
           settings: SettingsDep) -> dict:
    """Change a webhook's URL, description or active flag, or rotate its secret (``secret``)."""
    return service.change(db, settings, actor, webhook_id, body.model_dump(exclude_none=True))


@router.delete("/{webhook_id}", status_code=status.HTTP_204_NO_CONTENT, summary="Delete a webhook (admin)")
def delete(webhook_id: WebhookId, actor: AdminActor, db: DbDep) -> Response:
    service.remove(db, actor, webhook_id)
    return Response(status_code=204)


@router.post("/{webhook_id}/test", response_model=DeliveryOut, status_code=202, summary="Queue a ping (admin)")
def test(webhook_id: WebhookId, db: DbDep) -> dict:
    """Queue a ``ping`` delivery to the webhook (sent by the workers' delivery loop)."""
    return service.ping(db, webhook_id)


@router.get("/deliveries", response_model=DeliveryList, summary="The delivery log, newest first (admin)")
def deliveries(db: DbDep, settings: SettingsDep,
               webhook_id: Annotated[int | None, Query(ge=1, le=MAX_ID)] = None,
               status_: Annotated[str | None, Query(alias="status", description="pending, sending, delivered, failed")] = None,
               limit: Annotated[int, Query(ge=1)] = 100, offset: PageOffset = 0) -> dict:
    check_page_size(limit, settings)
    return service.delivery_log(db, webhook_id=webhook_id, status=status_, limit=limit, offset=offset)
