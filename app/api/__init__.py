"""REST API of trackvkf under ``/api/v1``.

Routers by resource: runs, jobs, profiles, wheels, reference data, analytics, health. Every router except
health depends on :func:`app.api.deps.get_principal`, the hook through which
authentication is added.
"""

from __future__ import annotations

from fastapi import APIRouter, Depends

from app.api import analytics, health, jobs, profiles, reference, runs, wheels
from app.api.deps import get_principal

__all__ = ["build_api_router", "API_PREFIX"]

API_PREFIX = "/api/v1"


def build_api_router() -> APIRouter:
    """The ``/api/v1`` router with all resource routers."""
    api = APIRouter(prefix=API_PREFIX)
    api.include_router(health.router)
    protected = APIRouter(dependencies=[Depends(get_principal)])
    for module in (runs, jobs, profiles, wheels, reference, analytics):
        protected.include_router(module.router)
    api.include_router(protected)
    return api
