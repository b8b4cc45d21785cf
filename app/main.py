"""The FastAPI application: ``create_app()``.

Run it with ``trackvkf serve`` or ``uvicorn --factory app.main:create_app``.

The routes are the same for every app: they read their settings, database and limiters from
the app that answers (``request.app.state``). FastAPI analyses a route's parameters and
dependencies (signatures, pydantic validators) when it is included, about a second for the
whole API; :func:`app_routes` does it once per process and every app built afterwards (the
tests build hundreds) takes the analysed routes as they are.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
from fastapi import FastAPI
from starlette.middleware.gzip import DEFAULT_EXCLUDED_CONTENT_TYPES, GZipMiddleware
from starlette.routing import BaseRoute

from app.api import API_PREFIX, build_api_router
from app.api.errors import install_error_handlers
from app.api.headers import SecurityHeadersMiddleware
from app.api.health import software_version
from app.api.login_page import (
    SWAGGER_ASSETS,
    docs_router,
    install_protected_docs,
    swagger_ui_assets,
)
from app.api.login_page import router as login_page_router
from app.api.metrics import install_metrics
from app.api.metrics import router as metrics_router
from app.api.oidc import router as oidc_router
from app.core.bytecache import ByteLRU
from app.core.config import ProductionConfigError
from app.core.logging import configure_logging
from app.core.ratelimit import RateLimiter
from app.core.runstore import RunStore
from app.db.display_arrays import DisplayArrays
from app.db.session import Database
from app.operations.heavy import install_heavy_limiter
from app.places.class_scheme import class_scheme
from app.settings import Settings, get_settings
from app.web import install_pages

__all__ = ["create_app", "app_routes", "check_production_database"]

#: answers not worth compressing again (already compressed formats)
_NOT_GZIPPED = (*DEFAULT_EXCLUDED_CONTENT_TYPES, "application/vnd.apache.parquet", "application/x-hdf5")

log = logging.getLogger(__name__)


@functools.cache
def app_routes() -> tuple[BaseRoute, ...]:
    """Every route of the application, in the order they are matched, analysed once per process.

    The REST API (``/api/v1``), the login page, the OpenID sign-in, ``/openapi.json`` and
    ``/docs`` with the Swagger UI's assets, the dashboard's pages and static files, ``/metrics``.
    They are included into an app built like the ones of :func:`create_app` (the same router
    defaults), whose route list is then shared: a route holds no state of an app (it reads
    ``request.app.state``), and FastAPI's analysis of it (parameters, dependencies, response
    models) is done here once instead of for every app. One consequence: an app's
    ``dependency_overrides`` do not reach these routes (the service sets none).
    """
    template = FastAPI(docs_url=None, redoc_url=None, openapi_url=None)
    template.include_router(build_api_router())
    template.include_router(login_page_router)
    template.include_router(oidc_router)
    template.include_router(docs_router)
    template.mount(SWAGGER_ASSETS, swagger_ui_assets(), name="swagger-ui")
    install_pages(template)  # dashboard: HTML pages at /, /runs/{id}, ..., /static, Plotly.js
    template.include_router(metrics_router)
    return tuple(template.router.routes)


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the application.

    Parameters
    ----------
    settings : Settings, optional
        Service settings; read from the environment (``TRACKVKF_*``) when
        omitted. The database must be migrated (``trackvkf migrate``).
    """
    settings = settings or get_settings()
    configure_logging(settings.log_level, settings.log_format)
    settings.check_production()
    class_scheme(settings)  # a bad TRACKVKF_PLACES_CLASS_SCHEME stops the start, naming the part at fault
    db = Database(settings.database_url, lock_wait_s=settings.db_lock_wait_s)
    if settings.is_production:
        check_production_database(db)
    store = RunStore(settings.run_store, settings.shared_store)
    store.root.mkdir(parents=True, exist_ok=True)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        swept = store.sweep_uploads(settings.upload_stale_after_s)
        if swept:
            log.info("removed %d abandoned upload(s) from the run store", swept)
        from app.db.migrate import current_revision  # alembic: imported only here

        try:
            revision = current_revision(settings.database_url)
        except Exception as exc:  # noqa: BLE001 - reported, the health check tells too
            log.warning("cannot read the database revision: %s", exc)
            revision = None
        if revision is None:
            log.warning("database %s is not migrated: run `trackvkf migrate`", settings.database_url)
        if settings.parse_isolated:
            from app.io.isolation import warm_up

            warm_up()  # the fork server of the upload parsers, started in the background
        yield
        db.dispose()

    app = FastAPI(
        title="trackvkf",
        version=software_version(),
        description=(
            "Track stiffness and wheel out-of-roundness from axle-box accelerations. "
            "Upload a run, follow its processing job, read indicator profiles and wheel OOR."
        ),
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
        openapi_url=None,
    )
    app.state.settings = settings
    app.state.db = db
    app.state.store = store
    app.state.login_limiter = RateLimiter(settings.login_rate_limit, settings.login_rate_window_s)
    app.state.login_address_limiter = RateLimiter(
        settings.login_address_rate_limit, settings.login_rate_window_s
    )
    app.state.upload_limiter = RateLimiter(settings.upload_rate_limit, settings.upload_rate_window_s)
    install_error_handlers(app)
    app.state.profile_cache = ByteLRU(settings.profile_cache_bytes)
    # profile answers computed at once in this process (the others wait: app.profiles.cache)
    app.state.display_arrays = DisplayArrays(settings.display_cache_bytes)  # zooms sliced from memory
    app.state.profile_limiter = anyio.CapacityLimiter(settings.profile_concurrency)
    app.state.profile_pending = {}  # answers being computed: asked again, awaited once
    install_heavy_limiter(app, settings.upload_ingest_concurrency)  # conversions of uploads at once
    app.add_middleware(GZipMiddleware, minimum_size=1024, compresslevel=5, exclude_content_types=_NOT_GZIPPED)
    app.add_middleware(SecurityHeadersMiddleware)  # CSP, framing, sniffing, referrer: every answer
    app.router.routes.extend(app_routes())  # the API, pages, docs, /metrics: analysed once per process
    install_protected_docs(app, {f"{API_PREFIX}/health", f"{API_PREFIX}/auth/login"})
    install_metrics(app)  # every request counted (outermost middleware)

    return app


def check_production_database(db: Database) -> None:
    """Refuse production mode while a user with printed demo credentials is active.

    Raises
    ------
    ProductionConfigError
        Naming the users (change their password or deactivate them first).
    """
    from app.db import auth_crud

    try:
        with db.read() as session:
            demo_users = auth_crud.active_demo_users(session)
    except Exception as exc:  # noqa: BLE001 - an unmigrated database is refused too
        raise ProductionConfigError(
            f"cannot check the users of {db.url}: {exc}; run `trackvkf migrate`"
        ) from None
    if demo_users:
        raise ProductionConfigError(
            "default credentials: user(s) "
            + ", ".join(repr(u) for u in demo_users)
            + " still have the password printed by `trackvkf demo`; change it "
            "(`trackvkf user set-password NAME`) or deactivate them before production use"
        )
