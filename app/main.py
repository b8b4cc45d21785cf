"""The FastAPI application: ``create_app()``.

Run it with ``trackvkf serve`` or ``uvicorn --factory app.main:create_app``.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI

from app.api import build_api_router
from app.api.errors import install_error_handlers
from app.api.health import software_version
from app.core.config import Settings, get_settings
from app.core.logging import configure_logging
from app.core.runstore import RunStore
from app.db.session import Database
from app.web import install_pages

__all__ = ["create_app"]

log = logging.getLogger(__name__)


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the application.

    Parameters
    ----------
    settings : Settings, optional
        Service settings; read from the environment (``TRACKVKF_*``) when
        omitted. The database must be migrated (``trackvkf migrate``).
    """
    settings = settings or get_settings()
    configure_logging(settings.log_level)
    db = Database(settings.database_url)
    store = RunStore(settings.run_store)
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
    )
    app.state.settings = settings
    app.state.db = db
    app.state.store = store
    install_error_handlers(app)
    app.include_router(build_api_router())
    install_pages(app)  # dashboard: HTML pages at /, /runs/{id}, ..., /static, Plotly.js

    return app
