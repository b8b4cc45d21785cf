"""Observability: Prometheus metrics (:mod:`~app.observability.metrics`, served by
:mod:`~app.observability.routes`) and the JSON log format (:mod:`app.core.logging`)."""
