"""Prometheus metrics at ``GET /metrics`` (admin only), with prometheus-client.

Two kinds of series:

*Counted by each API process* (:class:`MetricsMiddleware`, a pure ASGI
middleware around every request):

``trackvkf_http_requests_total{method,route,status}``
    requests by route *template* (``/api/v1/runs/{run_id}``: bounded labels) and status;
``trackvkf_http_request_duration_seconds{method,route}``
    latency histogram;
``trackvkf_uploads_total{outcome}``, ``trackvkf_upload_bytes_total``
    run uploads (``POST /api/v1/runs``) by outcome (created, duplicate,
    rejected, error) and the request bytes they brought.

With several API processes (``trackvkf serve --workers N``) every process
counts into files of one directory (prometheus-client's multi-process mode,
``PROMETHEUS_MULTIPROC_DIR``, which ``serve`` creates afresh when unset,
:func:`app.observability.multiproc.prepare_multiprocess_dir`) and a scrape adds them up, whichever
process answers it.

*Read from the database at scrape time* (:class:`DatabaseCollector`, cached
``_DB_CACHE_S`` seconds per process), so they are right whatever process or
host did the work (workers, other API hosts):

``trackvkf_jobs{status}``, ``trackvkf_queue_depth``, ``trackvkf_queue_oldest_age_seconds``,
``trackvkf_jobs_stuck``, ``trackvkf_workers_alive{mode}``
    the queue and the worker heartbeats (:mod:`app.operations.liveness`);
``trackvkf_job_seconds_per_run_second``
    histogram over the done jobs: wall seconds from the job's start to its
    end per second of measured run (1/x is the real-time factor);
``trackvkf_webhook_deliveries{status,outcome}``
    the delivery log by status and the coarse outcome of the last attempt;
``trackvkf_condition_flags{kind,new}``
    condition flags in the store;
``trackvkf_places_pending{state}``, ``trackvkf_places_pending_oldest_age_seconds``
    published runs whose places update (the publish step's follow-up) is still to come.

Alert rules on them: docs/operations.md.
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Iterator

from prometheus_client import CollectorRegistry, Counter, Histogram, generate_latest
from prometheus_client.core import GaugeMetricFamily, HistogramMetricFamily, Metric
from prometheus_client.exposition import CONTENT_TYPE_LATEST
from sqlalchemy import case, func, select

from app.db.models import ConditionFlag, Job, JobStatus, PlacesPending, Run, WebhookDelivery, utcnow
from app.db.session import Database
from app.observability.multiproc import multiprocess_mode
from app.operations.liveness import queue_health
from app.settings import Settings

__all__ = [
    "CONTENT_TYPE_LATEST",
    "MetricsMiddleware",
    "DatabaseCollector",
    "render",
    "UPLOAD_ROUTE",
]

#: the route whose requests are run uploads
UPLOAD_ROUTE = ("POST", "/api/v1/runs")
_METHODS = frozenset({"GET", "POST", "PUT", "PATCH", "DELETE", "HEAD", "OPTIONS"})
_LATENCY_BUCKETS = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 300.0)
_RATIO_BUCKETS = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)
_DB_CACHE_S = 5.0

REQUESTS = Counter("trackvkf_http_requests", "HTTP requests by route template and status",
                   ["method", "route", "status"])
LATENCY = Histogram("trackvkf_http_request_duration_seconds", "HTTP request latency by route template, s",
                    ["method", "route"], buckets=_LATENCY_BUCKETS)
UPLOADS = Counter("trackvkf_uploads", "Run uploads by outcome (created, duplicate, rejected, error)", ["outcome"])
UPLOAD_BYTES = Counter("trackvkf_upload_bytes", "Request bytes received by run uploads")


class RouteTemplates:
    """The full path template of a request's route (``/api/v1/runs/{run_id}``): a bounded label.

    The router puts the matched route object in ``scope["route"]``; its own
    ``path`` may be relative to the router that includes it, so the full
    templates are read once from the app's flattened routes
    (:func:`app.core.routing.iter_routes`) and the one whose pattern matches the
    request's path is taken. A request that matched no route is ``(unmatched)``.
    """

    def __init__(self) -> None:
        self._by_route: dict[int, list[tuple[str, re.Pattern]]] | None = None

    def _build(self, app) -> dict[int, list[tuple[str, re.Pattern]]]:
        from starlette.routing import compile_path

        from app.core.routing import iter_routes

        out: dict[int, list[tuple[str, re.Pattern]]] = {}
        for item in iter_routes(app):
            route = getattr(item, "original_route", item)
            path = getattr(item, "path", None) or getattr(route, "path", None)
            if not isinstance(path, str):
                continue
            regex = compile_path(path if not hasattr(route, "app") or hasattr(route, "endpoint")
                                 else path.rstrip("/") + "/{path:path}")[0]
            out.setdefault(id(route), []).append((path, regex))
        return out

    def __call__(self, scope: dict) -> str:
        route = scope.get("route")
        if route is None:
            return "(unmatched)"
        if self._by_route is None:
            self._by_route = self._build(scope["app"])
        candidates = self._by_route.get(id(route), [])
        path = scope.get("path", "")
        for template, regex in candidates:
            if regex.match(path):
                return template
        if candidates:
            return candidates[0][0]
        own = getattr(route, "path", None)
        return own if isinstance(own, str) else "(unmatched)"


class MetricsMiddleware:
    """Pure ASGI middleware counting every HTTP request by route template and status."""

    def __init__(self, app) -> None:
        self.app = app
        self.templates = RouteTemplates()

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t0 = time.perf_counter()
        status = [500]
        received = [0]

        async def counting_receive():
            message = await receive()
            if message.get("type") == "http.request":
                received[0] += len(message.get("body", b""))
            return message

        async def status_send(message) -> None:
            if message["type"] == "http.response.start":
                status[0] = int(message["status"])
            await send(message)

        try:
            await self.app(scope, counting_receive, status_send)
        finally:
            method = scope.get("method", "GET")
            method = method if method in _METHODS else "OTHER"
            route = self.templates(scope)
            REQUESTS.labels(method, route, str(status[0])).inc()
            LATENCY.labels(method, route).observe(time.perf_counter() - t0)
            if (method, route) == UPLOAD_ROUTE:
                code = status[0]
                outcome = ("created" if code == 201 else "duplicate" if code == 200
                           else "rejected" if code < 500 else "error")
                UPLOADS.labels(outcome).inc()
                UPLOAD_BYTES.inc(received[0])


class DatabaseCollector:
    """Collector of the series read from the database (see the module), cached ``cache_s`` seconds."""

    def __init__(self, db: Database, settings: Settings, cache_s: float = _DB_CACHE_S) -> None:
        self.db, self.settings, self.cache_s = db, settings, cache_s
        self._lock = threading.Lock()
        self._cached: tuple[float, list[Metric]] | None = None

    def collect(self) -> Iterator[Metric]:
        with self._lock:
            now = time.monotonic()
            if self._cached is None or now - self._cached[0] > self.cache_s:
                self._cached = (now, self._read())
            return iter(self._cached[1])

    def _read(self) -> list[Metric]:
        out: list[Metric] = []
        with self.db.read() as s:
            jobs = GaugeMetricFamily("trackvkf_jobs", "Jobs by status", labels=["status"])
            counts = dict(s.execute(select(Job.status, func.count()).group_by(Job.status)).all())
            for st in JobStatus.ALL:
                jobs.add_metric([st], int(counts.get(st, 0)))
            out.append(jobs)

            q = queue_health(s, stale_after_s=self.settings.worker_stale_after_s,
                             stuck_after_s=self.settings.health_stuck_after_s)
            out.append(GaugeMetricFamily("trackvkf_queue_depth", "Jobs queued", value=q.queued))
            out.append(GaugeMetricFamily("trackvkf_queue_oldest_age_seconds",
                                         "Age of the oldest queued job, s (0: none queued)",
                                         value=q.oldest_queued_age_s or 0.0))
            out.append(GaugeMetricFamily("trackvkf_jobs_stuck", "Running jobs without progress for "
                                         "TRACKVKF_HEALTH_STUCK_AFTER_S", value=q.stuck))
            workers = GaugeMetricFamily("trackvkf_workers_alive", "Worker processes alive by mode", labels=["mode"])
            by_mode: dict[str, int] = {"local": 0, "procrastinate": 0}
            for w in q.workers_alive:
                by_mode[w.mode] = by_mode.get(w.mode, 0) + 1
            for mode, n in sorted(by_mode.items()):
                workers.add_metric([mode], n)
            out.append(workers)
            out.append(GaugeMetricFamily("trackvkf_workers_lost", "Worker processes silent for longer than "
                                         "TRACKVKF_WORKER_STALE_AFTER_S (died)", value=q.workers_lost))

            out.append(self._ratio_histogram(s))

            deliveries = GaugeMetricFamily("trackvkf_webhook_deliveries",
                                           "Webhook deliveries by status and outcome of the last attempt",
                                           labels=["status", "outcome"])
            outcome = case(
                (WebhookDelivery.attempts == 0, "none"),
                (WebhookDelivery.last_error.is_(None), "delivered"),
                (WebhookDelivery.last_error.like("HTTP %"), "http_error"),
                (WebhookDelivery.last_error.like("refused%"), "refused"),
                else_="no_answer")
            for st, oc, n in s.execute(select(WebhookDelivery.status, outcome, func.count())
                                       .group_by(WebhookDelivery.status, outcome)).all():
                deliveries.add_metric([st, oc], int(n))
            out.append(deliveries)

            flags = GaugeMetricFamily("trackvkf_condition_flags", "Condition flags in the store by kind; "
                                      "new: not seen in an earlier run", labels=["kind", "new"])
            for kind, new, n in s.execute(select(ConditionFlag.kind, ConditionFlag.is_new, func.count())
                                          .group_by(ConditionFlag.kind, ConditionFlag.is_new)).all():
                flags.add_metric([str(kind), "true" if new else "false"], int(n))
            out.append(flags)

            # the places follow-up of the publish step (app.places.followup): runs whose places lag
            pending = GaugeMetricFamily("trackvkf_places_pending", "Published runs whose places update is still "
                                        "to come: waiting (due or never tried), retrying (failed, in back-off), "
                                        "gave_up", labels=["state"])
            state = case((PlacesPending.gave_up.is_(True), "gave_up"),
                         (PlacesPending.attempts > 0, "retrying"), else_="waiting")
            counts = dict(s.execute(select(state, func.count()).group_by(state)).all())
            for st in ("waiting", "retrying", "gave_up"):
                pending.add_metric([st], int(counts.get(st, 0)))
            out.append(pending)
            oldest = s.scalar(select(func.min(PlacesPending.queued_at)).where(PlacesPending.gave_up.is_(False)))
            out.append(GaugeMetricFamily("trackvkf_places_pending_oldest_age_seconds",
                                         "Age of the oldest pending places update, s (0: none)",
                                         value=max((utcnow() - oldest).total_seconds(), 0.0) if oldest else 0.0))
        return out

    @staticmethod
    def _ratio_histogram(s) -> HistogramMetricFamily:
        """Wall seconds per run-second of the done jobs, bucketed in SQL (one pass over the done jobs)."""
        seconds = (func.julianday(Job.finished_at) - func.julianday(Job.started_at)) * 86400.0 \
            if s.get_bind().dialect.name == "sqlite" else func.extract("epoch", Job.finished_at - Job.started_at)
        ratio = seconds / Run.duration_s
        done = (Job.status == JobStatus.DONE, Job.started_at.is_not(None), Job.finished_at.is_not(None),
                Run.duration_s > 0)
        cols = [func.count(), func.coalesce(func.sum(ratio), 0.0)]
        cols += [func.count().filter(ratio <= b) for b in _RATIO_BUCKETS]
        row = s.execute(select(*cols).select_from(Job).join(Run, Run.id == Job.run_id).where(*done)).one()
        total, total_sum, cumulative = int(row[0]), float(row[1] or 0.0), [int(v or 0) for v in row[2:]]
        buckets = [(str(b), n) for b, n in zip(_RATIO_BUCKETS, cumulative, strict=True)] + [("+Inf", total)]
        return HistogramMetricFamily("trackvkf_job_seconds_per_run_second",
                                     "Wall seconds of a done job (start to end) per second of measured run",
                                     buckets=buckets, sum_value=total_sum)


def _counting_in_files() -> bool:
    """Whether this process's metrics live in the multi-process directory (decided when
    prometheus-client was first imported: the variable set at that time)."""
    from prometheus_client import values

    return multiprocess_mode() and values.ValueClass is not values.MutexValue


def render(db: Database, settings: Settings, collector: DatabaseCollector | None = None) -> bytes:
    """The exposition text of a scrape: this process's (or all API processes') counters and the
    database series."""
    registry = CollectorRegistry()
    if _counting_in_files():
        from prometheus_client import multiprocess

        multiprocess.MultiProcessCollector(registry)
        text = generate_latest(registry)
    else:
        from prometheus_client import REGISTRY

        text = generate_latest(REGISTRY)
    db_registry = CollectorRegistry()
    db_registry.register(collector or DatabaseCollector(db, settings))
    return text + generate_latest(db_registry)
