"""Queries and changes of the assets (known discontinuities). Every function takes an open session;
the caller decides the transaction."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy import delete, func, insert, or_, select
from sqlalchemy.orm import Session

from app.db.models import Asset, utcnow

__all__ = ["ASSET_COLUMNS", "replace_assets", "list_assets", "count_assets", "delete_asset", "line_assets"]

#: columns of an asset as the API answers it
ASSET_COLUMNS = ("id", "line_id", "track", "type", "km", "km_to", "name", "lon", "lat")
_BATCH = 20_000


def replace_assets(session: Session, rows: Sequence[dict[str, Any]]) -> tuple[int, int]:
    """Delete the stored assets of the (line_id, track) pairs in ``rows``, insert ``rows``.

    Returns
    -------
    (int, int)
        Inserted, deleted.
    """
    pairs = sorted({(r["line_id"], r["track"]) for r in rows}, key=lambda p: (p[0], p[1] or ""))
    deleted = 0
    for line_id, track in pairs:
        cond = Asset.track.is_(None) if track is None else Asset.track == track
        deleted += int(session.execute(delete(Asset).where(Asset.line_id == line_id, cond)).rowcount or 0)
    now = utcnow()
    for i in range(0, len(rows), _BATCH):
        session.execute(insert(Asset), [{**r, "imported_at": now} for r in rows[i:i + _BATCH]])
    return len(rows), deleted


def _filters(line_id: str | None, track: str | None, type_: str | None) -> list:
    cond: list = []
    if line_id is not None:
        cond.append(Asset.line_id == line_id)
    if track is not None:  # an asset without a track is on every track of its line
        cond.append(or_(Asset.track == track, Asset.track.is_(None)))
    if type_ is not None:
        cond.append(Asset.type == type_)
    return cond


def list_assets(session: Session, *, line_id: str | None = None, track: str | None = None,
                type_: str | None = None, limit: int | None = None, offset: int = 0) -> list[Asset]:
    """Assets by line and km."""
    q = select(Asset).where(*_filters(line_id, track, type_)).order_by(Asset.line_id, Asset.km, Asset.id)
    if limit is not None:
        q = q.limit(limit).offset(offset)
    return list(session.scalars(q))


def count_assets(session: Session, *, line_id: str | None = None, track: str | None = None,
                 type_: str | None = None) -> int:
    """Number of assets matching the filters."""
    return int(session.scalar(select(func.count()).select_from(Asset).where(*_filters(line_id, track, type_))) or 0)


def line_assets(session: Session, line_id: str, track: str) -> list[Asset]:
    """The assets on a line and track (those without a track included), by km."""
    return list_assets(session, line_id=line_id, track=track)


def delete_asset(session: Session, asset_id: int) -> bool:
    """Delete one asset; whether it existed."""
    return bool(session.execute(delete(Asset).where(Asset.id == asset_id)).rowcount)


