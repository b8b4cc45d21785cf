"""Alerts: the SSRF policy of webhook targets (:mod:`~app.alerts.url_policy`) and the bounded,
pinned request that delivers one (:mod:`~app.alerts.transport`)."""
