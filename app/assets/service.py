"""The assets service: bounded parse of an upload, one-transaction replace per line and track,
queries and delete."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sqlalchemy.orm import Session

from app.db import assets_crud
from app.db.models import Asset
from app.db.session import Database

__all__ = ["parse_upload", "store_assets", "asset_dict", "find_assets", "remove_asset"]


def parse_upload(settings: Any, data: bytes, filename: str | None) -> list[dict[str, Any]]:
    """:func:`app.assets.reader.read_assets` — in a child process within the parse budget
    (``TRACKVKF_PARSE_*``) unless ``settings.parse_isolated`` is off, as every other upload.

    Raises
    ------
    RunFileError
        Naming the row/feature and column/property, or ``file`` (too big, too slow, not readable).
    """
    if not settings.parse_isolated:
        from app.assets.reader import read_assets

        return read_assets(data, filename)
    from app.io.isolation import budget_from, run_bounded

    return run_bounded("app.assets.reader:read_assets", (data, filename), budget=budget_from(settings, len(data)),
                       what="the asset file")


def store_assets(db: Database, rows: list[dict[str, Any]],
                 audit: Callable[[Session, int, int], None] | None = None) -> tuple[int, int]:
    """Replace the stored assets of every (line, track) in ``rows`` by ``rows``, in one transaction
    with ``audit(session, imported, replaced)``. Returns (imported, replaced)."""
    with db.write() as session:
        imported, replaced = assets_crud.replace_assets(session, rows)
        if audit is not None:
            audit(session, imported, replaced)
    return imported, replaced


def asset_dict(a: Asset) -> dict[str, Any]:
    """An asset as the API answers it."""
    return {c: getattr(a, c) for c in assets_crud.ASSET_COLUMNS}


def find_assets(db: Database, *, line_id: str | None = None, track: str | None = None, type_: str | None = None,
                limit: int = 10_000, offset: int = 0) -> tuple[list[dict[str, Any]], int]:
    """Assets matching the filters (an asset without a track is on every track) and their total."""
    with db.read() as session:
        items = assets_crud.list_assets(session, line_id=line_id, track=track, type_=type_, limit=limit,
                                        offset=offset)
        total = assets_crud.count_assets(session, line_id=line_id, track=track, type_=type_)
        return [asset_dict(a) for a in items], total


def remove_asset(db: Database, asset_id: int, audit: Callable[[Session], None] | None = None) -> bool:
    """Delete one asset (with ``audit(session)`` in the same transaction); whether it existed."""
    with db.write() as session:
        found = assets_crud.delete_asset(session, asset_id)
        if found and audit is not None:
            audit(session)
        return found
