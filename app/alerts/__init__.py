"""Alerts: the webhooks that receive them, administered with their delivery log
(:mod:`~app.alerts.webhooks`), the SSRF policy of webhook targets (:mod:`~app.core.url_policy`)
and the bounded, pinned request that delivers one (:mod:`~app.alerts.transport`)."""
