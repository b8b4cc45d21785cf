"""``GET /metrics``: the Prometheus exposition (admin only), and :func:`install_metrics`.

Access: an admin principal (an admin API key: configure Prometheus with
``authorization: {credentials: <key>}``, or a session). The series and alert
rules: :mod:`app.observability.metrics`, docs/operations.md.
"""

from __future__ import annotations

from fastapi import APIRouter, Depends, FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from app.api.deps import require_role
from app.observability.metrics import (
    CONTENT_TYPE_LATEST,
    DatabaseCollector,
    MetricsMiddleware,
    render,
)

__all__ = ["router", "install_metrics"]

router = APIRouter(tags=["operations"])


@router.get("/metrics", dependencies=[Depends(require_role("admin"))], response_class=Response,
            summary="Prometheus metrics (admin)",
            responses={200: {"content": {CONTENT_TYPE_LATEST: {}}, "description": "Prometheus text format"}})
async def metrics(request: Request) -> Response:
    """Requests by route and status with latency histograms, uploads and their bytes, jobs by
    state, queue depth and age, workers alive, processing seconds per run-second, webhook
    deliveries by outcome, condition flags (docs/operations.md)."""
    state = request.app.state
    body = await run_in_threadpool(render, state.db, state.settings, state.metrics_collector)
    return Response(body, media_type=CONTENT_TYPE_LATEST)


def install_metrics(app: FastAPI) -> None:
    """Count every request of ``app`` (:class:`~app.observability.metrics.MetricsMiddleware`) and give
    it the collector that ``/metrics`` (:data:`router`, among the app's routes) reads."""
    app.state.metrics_collector = DatabaseCollector(app.state.db, app.state.settings)
    app.add_middleware(MetricsMiddleware)
