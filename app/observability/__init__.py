"""Observability: Prometheus metrics (:mod:`~app.observability.metrics`, served by
:mod:`~app.api.metrics`) and the JSON log format (:mod:`app.core.logging`)."""
