"""What the routes depend on: the app's settings, database and run store, who asks, and the
shared parameters.

Everything the routes need hangs on ``app.state`` (set by :func:`app.main.create_app`),
so a test can build an app with its own settings and database. Who may call a route is
decided in :mod:`app.api.access`; the shared query and path parameters and their checks
are :mod:`app.api.params`. This module gathers what a route module imports.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from app.api.access import (
    API_KEY_HEADER,
    CSRF_COOKIE,
    CSRF_HEADER,
    SESSION_COOKIE,
    Actor,
    PageLogin,
    Principal,
    RoleRequirement,
    acting,
    client_ip,
    get_principal,
    iter_routes,
    public,
    require_page_login,
    require_role,
    route_policy,
)
from app.api.params import (
    KM_BOUND,
    IdQuery,
    JobId,
    PageOffset,
    RunId,
    Wheel,
    WheelQ,
    check_km,
    check_page_size,
    km_query,
    parse_time,
    parse_time_range,
    wheel_param,
)
from app.core.runstore import RunStore
from app.db.session import Database
from app.settings import Settings

__all__ = [
    "get_settings",
    "get_db",
    "get_store",
    "SettingsDep",
    "DbDep",
    "StoreDep",
    "PrincipalDep",
    "ViewerDep",
    "EngineerDep",
    "AdminDep",
    "ViewerActor",
    "EngineerActor",
    "AdminActor",
    # from app.api.access
    "Actor",
    "acting",
    "API_KEY_HEADER",
    "CSRF_COOKIE",
    "CSRF_HEADER",
    "SESSION_COOKIE",
    "PageLogin",
    "Principal",
    "RoleRequirement",
    "client_ip",
    "get_principal",
    "iter_routes",
    "public",
    "require_page_login",
    "require_role",
    "route_policy",
    # from app.api.params
    "KM_BOUND",
    "JobId",
    "IdQuery",
    "PageOffset",
    "RunId",
    "Wheel",
    "WheelQ",
    "check_km",
    "check_page_size",
    "km_query",
    "parse_time",
    "parse_time_range",
    "wheel_param",
]


# coroutines: FastAPI runs a plain function dependency in a worker thread (a hop of
# ~0.1 ms each per request), and these only read the app state


async def get_settings(request: Request) -> Settings:
    """Settings of the running app."""
    return request.app.state.settings


async def get_db(request: Request) -> Database:
    """Database of the running app."""
    return request.app.state.db


async def get_store(request: Request) -> RunStore:
    """Run store of the running app."""
    return request.app.state.store


SettingsDep = Annotated[Settings, Depends(get_settings)]
DbDep = Annotated[Database, Depends(get_db)]
StoreDep = Annotated[RunStore, Depends(get_store)]
PrincipalDep = Annotated[Principal, Depends(get_principal)]
ViewerDep = Annotated[Principal, Depends(require_role("viewer"))]
EngineerDep = Annotated[Principal, Depends(require_role("engineer"))]
AdminDep = Annotated[Principal, Depends(require_role("admin"))]
#: who writes, with the client's address (:class:`~app.core.security.Actor`), admitted by role
ViewerActor = Annotated[Actor, Depends(acting("viewer"))]
EngineerActor = Annotated[Actor, Depends(acting("engineer"))]
AdminActor = Annotated[Actor, Depends(acting("admin"))]
