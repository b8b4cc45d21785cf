"""Alerts: the SSRF policy of webhook targets (:mod:`~app.core.url_policy`) and the bounded,
pinned request that delivers one (:mod:`~app.alerts.transport`)."""
