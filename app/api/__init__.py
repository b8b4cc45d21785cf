"""REST API of trackvkf under ``/api/v1``.

Routers by resource: runs, jobs, profiles, wheels, reference data, analytics,
condition (the segment condition store), channel maps, line geometry, webhooks (admin), health, auth, audit. Every
route declares its access policy through a dependency (see
:func:`app.api.deps.route_policy`): ``public`` (health, login), or
``require_role(role)`` — the resource routers below get ``viewer`` for all their
routes, and the state-changing routes add ``engineer`` or ``admin`` themselves.
"""

from __future__ import annotations

from fastapi import APIRouter, Depends

from app.api import (
    analytics,
    assets,
    audit,
    auth,
    channel_maps,
    condition,
    condition_effects,
    condition_report,
    condition_sections,
    geometry,
    health,
    impacts,
    jobs,
    places,
    profiles,
    rail_findings,
    reference,
    runs,
    spectrogram,
    webhooks,
    wheels,
)
from app.api.deps import public, require_role
from app.core.config import API_PREFIX

__all__ = ["build_api_router", "API_PREFIX"]


def build_api_router() -> APIRouter:
    """The ``/api/v1`` router with all resource routers."""
    api = APIRouter(prefix=API_PREFIX)
    api.include_router(health.router, dependencies=[Depends(public)])
    api.include_router(auth.login_router)
    protected = APIRouter(dependencies=[Depends(require_role("viewer"))])
    for module in (
        runs, jobs, profiles, impacts, wheels, spectrogram, reference, analytics, condition,
        condition_effects, condition_sections, condition_report, places, rail_findings, auth, audit, channel_maps,
        geometry, webhooks, assets,
    ):
        protected.include_router(module.router)
    api.include_router(protected)
    return api
