"""Dependencies of the API routes: settings, database, run store, principal.

Everything the routes need hangs on ``app.state`` (set by
:func:`app.main.create_app`), so a test can build an app with its own settings
and database.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

from fastapi import Depends, Path, Request

from app.core.config import Settings
from app.core.runstore import RunStore
from app.db.session import Database

__all__ = [
    "Principal",
    "get_principal",
    "get_settings",
    "get_db",
    "get_store",
    "SettingsDep",
    "DbDep",
    "StoreDep",
    "PrincipalDep",
    "RunId",
    "JobId",
]


@dataclass(frozen=True)
class Principal:
    """Who makes a request.

    Attributes
    ----------
    name : str
        User name or API key name.
    role : str
        ``viewer``, ``engineer`` or ``admin``.
    kind : str
        ``anonymous`` (no authentication configured), ``user`` or ``api_key``.
    """

    name: str
    role: Literal["viewer", "engineer", "admin"]
    kind: Literal["anonymous", "user", "api_key"] = "anonymous"


def get_settings(request: Request) -> Settings:
    """Settings of the running app."""
    return request.app.state.settings


def get_db(request: Request) -> Database:
    """Database of the running app."""
    return request.app.state.db


def get_store(request: Request) -> RunStore:
    """Run store of the running app."""
    return request.app.state.store


def get_principal(request: Request) -> Principal:
    """The principal of a request.

    Every resource router depends on this hook. Today it returns the local
    anonymous principal configured in the settings (``anonymous_principal``,
    ``anonymous_role``); the access-control work replaces it with session
    cookie / API key authentication (raising 401/403) without touching the
    routes.
    """
    settings: Settings = request.app.state.settings
    return Principal(
        name=settings.anonymous_principal, role=settings.anonymous_role, kind="anonymous"
    )


SettingsDep = Annotated[Settings, Depends(get_settings)]
DbDep = Annotated[Database, Depends(get_db)]
StoreDep = Annotated[RunStore, Depends(get_store)]
PrincipalDep = Annotated[Principal, Depends(get_principal)]

_MAX_ID = 2**31 - 1
RunId = Annotated[int, Path(ge=1, le=_MAX_ID, description="Run id")]
JobId = Annotated[int, Path(ge=1, le=_MAX_ID, description="Job id")]
