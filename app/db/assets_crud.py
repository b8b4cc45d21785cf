"""Queries and changes of the assets (known discontinuities). Every function takes an open session;
the caller decides the transaction.

Reads see the **live** rows only: those whose (line, track) pointer (:class:`AssetLine`) names
their import. An import's writes are each bounded (:mod:`app.assets.store` drives them, one short
transaction each): :func:`start_import`, :func:`insert_rows` (a batch), :func:`switch_lines` (the
pointers of the import's pairs: what makes it live, at once), :func:`delete_garbage` (a batch of
rows no pointer names, set-based).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy import delete, exists, func, insert, or_, select, tuple_, update
from sqlalchemy.orm import Session

from app.db.models import NO_TRACK, Asset, AssetImport, AssetLine, utcnow

__all__ = ["ASSET_COLUMNS", "list_assets", "count_assets", "delete_asset", "line_assets", "assets_near",
           "start_import", "insert_rows", "switch_lines", "finish_import", "abandon_stale_imports", "abandoned_lines",
           "delete_garbage", "lines_of", "track_key"]

#: (line, track) pairs named in one statement (SQLite's expression depth and variable limits)
_PAIRS_PER_STATEMENT = 400
#: columns of an asset as the API answers it
ASSET_COLUMNS = ("id", "line_id", "track", "type", "km", "km_to", "name", "lon", "lat")


def track_key(track: str | None) -> str:
    """The pointer's track of an asset's ``track`` (None: :data:`NO_TRACK`, every track)."""
    return NO_TRACK if track is None else track


def _live():
    """An asset row is live when its pair's pointer names its import."""
    return exists().where(AssetLine.line_id == Asset.line_id,
                          AssetLine.track == func.coalesce(Asset.track, NO_TRACK),
                          AssetLine.import_id == Asset.import_id)


def _filters(line_id: str | None, track: str | None, type_: str | None) -> list:
    cond: list = [_live()]
    if line_id is not None:
        cond.append(Asset.line_id == line_id)
    if track is not None:  # an asset without a track is on every track of its line
        cond.append(or_(Asset.track == track, Asset.track.is_(None)))
    if type_ is not None:
        cond.append(Asset.type == type_)
    return cond


def list_assets(session: Session, *, line_id: str | None = None, track: str | None = None,
                type_: str | None = None, limit: int | None = None, offset: int = 0) -> list[Asset]:
    """Live assets by line and km."""
    q = select(Asset).where(*_filters(line_id, track, type_)).order_by(Asset.line_id, Asset.km, Asset.id)
    if limit is not None:
        q = q.limit(limit).offset(offset)
    return list(session.scalars(q))


def count_assets(session: Session, *, line_id: str | None = None, track: str | None = None,
                 type_: str | None = None) -> int:
    """Number of live assets matching the filters."""
    return int(session.scalar(select(func.count()).select_from(Asset).where(*_filters(line_id, track, type_))) or 0)


def line_assets(session: Session, line_id: str, track: str) -> list[Asset]:
    """The live assets on a line and track (those without a track included), by km."""
    return list_assets(session, line_id=line_id, track=track)


def max_extent_km(session: Session, line_id: str, track: str) -> float | None:
    """The longest extent (km) of the live assets on a line and track (those without a track
    included); None when the line has no assets there."""
    got = session.scalar(select(func.max(AssetLine.max_extent_km)).where(
        AssetLine.line_id == line_id, AssetLine.track.in_([track, NO_TRACK])))
    return None if got is None else float(got)


def assets_near(session: Session, line_id: str, track: str, lo_km: float, hi_km: float, extent_km: float, *,
                limit: int, types: Sequence[str] = ()) -> tuple[list[Asset], int]:
    """The live assets on a line and track overlapping ``[lo_km, hi_km]``, by km, at most ``limit``, and
    how many there are in all.

    One indexed range query: an asset overlapping the window starts at most ``extent_km`` (the
    line's longest asset, :func:`max_extent_km`) before it.
    """
    where = [*_filters(line_id, track, None), Asset.km >= lo_km - extent_km, Asset.km <= hi_km,
             func.coalesce(Asset.km_to, Asset.km) >= lo_km]
    if types:
        where.append(Asset.type.in_(list(types)))
    rows = list(session.scalars(select(Asset).where(*where).order_by(Asset.km, Asset.id).limit(limit)))
    if len(rows) < limit:
        return rows, len(rows)
    return rows, int(session.scalar(select(func.count()).select_from(Asset).where(*where)) or 0)


def delete_asset(session: Session, asset_id: int) -> bool:
    """Delete one live asset (its pair's count follows); whether it existed."""
    got = session.execute(select(Asset.line_id, Asset.track).where(Asset.id == asset_id, _live())).first()
    if got is None:
        return False
    session.execute(delete(Asset).where(Asset.id == asset_id).execution_options(synchronize_session=False))
    session.execute(update(AssetLine).where(AssetLine.line_id == got.line_id,
                                            AssetLine.track == track_key(got.track))
                    .values(n_assets=AssetLine.n_assets - 1))
    return True


# --- an import's steps (each in a short transaction of its own) ----------------------------------
def start_import(session: Session, created_by: str | None, n_rows: int) -> int:
    """A new import in state ``writing``; its id."""
    imp = AssetImport(state="writing", n_rows=n_rows, created_by=created_by, created_at=utcnow())
    session.add(imp)
    session.flush()
    return int(imp.id)


def insert_rows(session: Session, import_id: int, rows: Sequence[dict[str, Any]]) -> int:
    """Insert a batch of an import's rows (not live yet); how many."""
    if rows:
        now = utcnow()
        session.execute(insert(Asset), [{**r, "import_id": import_id, "imported_at": now} for r in rows])
    return len(rows)


def lines_of(rows: Sequence[dict[str, Any]]) -> dict[tuple[str, str], tuple[int, float]]:
    """The (line, pointer track) pairs of rows: their number of assets and longest extent (km)."""
    out: dict[tuple[str, str], tuple[int, float]] = {}
    for r in rows:
        key = (r["line_id"], track_key(r["track"]))
        n, ext = out.get(key, (0, 0.0))
        out[key] = (n + 1, max(ext, 0.0 if r["km_to"] is None else r["km_to"] - r["km"]))
    return out


def switch_lines(session: Session, import_id: int, lines: dict[tuple[str, str], tuple[int, float]]) -> int:
    """Point every pair of ``lines`` at the import (its rows live at this commit); the number of
    assets the pairs held before (now garbage)."""
    keys = list(lines)
    held = 0
    for i in range(0, len(keys), _PAIRS_PER_STATEMENT):
        chunk = tuple_(AssetLine.line_id, AssetLine.track).in_(keys[i:i + _PAIRS_PER_STATEMENT])
        held += int(session.scalar(select(func.coalesce(func.sum(AssetLine.n_assets), 0)).where(chunk)) or 0)
        session.execute(delete(AssetLine).where(chunk).execution_options(synchronize_session=False))
    session.execute(insert(AssetLine), [
        {"line_id": ln, "track": tr, "import_id": import_id, "n_assets": n, "max_extent_km": ext}
        for (ln, tr), (n, ext) in lines.items()])
    session.execute(update(AssetImport).where(AssetImport.id == import_id).values(state="live"))
    return held


def finish_import(session: Session, import_id: int, state: str) -> None:
    """Set an import's state (``abandoned``: its rows are garbage)."""
    session.execute(update(AssetImport).where(AssetImport.id == import_id).values(state=state))


def abandon_stale_imports(session: Session, older_than) -> int:
    """Imports still ``writing`` created before ``older_than`` (their writer died): abandoned."""
    return int(session.execute(update(AssetImport).where(
        AssetImport.state == "writing", AssetImport.created_at < older_than).values(state="abandoned")).rowcount or 0)


def abandoned_lines(session: Session) -> list[tuple[str, str]]:
    """The (line, pointer track) pairs holding rows of abandoned imports."""
    return [(ln, tr) for ln, tr in session.execute(
        select(Asset.line_id, func.coalesce(Asset.track, NO_TRACK)).distinct().where(
            Asset.import_id.in_(select(AssetImport.id).where(AssetImport.state == "abandoned"))))]


def delete_garbage(session: Session, line_id: str, track: str, limit: int) -> int:
    """Delete up to ``limit`` rows of a line and pointer track that are not live and whose import is
    not being written (replaced or abandoned), set-based; how many."""
    cond = Asset.track.is_(None) if track == NO_TRACK else Asset.track == track
    writing = select(AssetImport.id).where(AssetImport.state == "writing")
    ids = (select(Asset.id).where(Asset.line_id == line_id, cond, ~_live(), Asset.import_id.not_in(writing))
           .limit(limit).scalar_subquery())
    return int(session.execute(delete(Asset).where(Asset.id.in_(ids))
                               .execution_options(synchronize_session=False)).rowcount or 0)
