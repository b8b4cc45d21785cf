"""The webhooks' settings group (``TRACKVKF_WEBHOOK_*``): how alerts are delivered (:mod:`app.alerts.webhooks`)."""

from __future__ import annotations

from pydantic import Field, field_validator

from app.core.config import SettingsGroup

__all__ = ["WebhookSettings"]


class WebhookSettings(SettingsGroup):
    """Webhooks: delivery time limits, receivers' networks, retries.

    Attributes
    ----------
    webhook_timeout_s : float
        Total time of one webhook request, s: name resolution, connection,
        TLS, sending and the receiver's answer together, however slowly the
        receiver trickles bytes.
    webhook_max_answer_bytes : int
        Most bytes of a receiver's answer body read (and discarded), bytes.
    webhook_concurrency : int
        Deliveries a worker process sends at once (one per webhook at a time):
        a slow receiver holds one of them, not the others.
    webhook_allowed_networks : str
        Networks (CIDR, comma separated: ``10.20.0.0/16,192.168.5.7/32``) that
        webhook receivers may be in although private, loopback or otherwise
        not public (on-premises receivers). Default: none (public addresses
        only). See docs/security.md ("Webhooks: SSRF policy").
    webhook_secret_grace_s : float
        After a secret is rotated (``PATCH /webhooks/{id}`` with ``secret``),
        deliveries carry a signature with the previous secret too for this
        long, s, so receivers can switch over.
    webhook_max_attempts : int
        Attempts of a delivery before it is given up.
    webhook_retry_base_s, webhook_retry_max_s : float
        Back-off after the n-th failed attempt: ``base · 2^(n−1)`` seconds, at most ``max``.
    webhook_poll_s : float
        Pause of a worker's delivery loop when nothing is due, s.
    """

    webhook_timeout_s: float = Field(default=5.0, gt=0, le=120)
    webhook_max_answer_bytes: int = Field(default=64 * 1024, ge=0, le=16 * 1024 * 1024)
    webhook_concurrency: int = Field(default=4, ge=1, le=64)
    webhook_allowed_networks: str = Field(default="", max_length=4000)
    webhook_secret_grace_s: float = Field(default=24 * 3600.0, ge=0)
    webhook_max_attempts: int = Field(default=8, ge=1, le=100)
    webhook_retry_base_s: float = Field(default=5.0, gt=0)
    webhook_retry_max_s: float = Field(default=3600.0, gt=0)
    webhook_poll_s: float = Field(default=1.0, gt=0)

    @field_validator("webhook_allowed_networks")
    @classmethod
    def _check_networks(cls, value: str) -> str:
        from app.core.url_policy import parse_networks

        parse_networks(value)  # ValueError naming the entry
        return value
