"""The routes of a FastAPI app, flattened: what the access policy checks and the metrics label by."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

__all__ = ["iter_routes"]


def iter_routes(app) -> Iterator[Any]:
    """Every route of an app with its effective dependencies (included routers flattened).

    Items have ``path``, ``methods`` and, for FastAPI routes, ``dependant``
    (None for mounts and plain Starlette routes).
    """
    try:
        from fastapi.routing import iter_route_contexts
    except ImportError:  # older FastAPI: included routes are flattened into app.routes
        yield from app.routes
        return
    yield from iter_route_contexts(app.routes)
