"""The assets service: an import (bounded parse, caps, bounded writes, one short switch), the
queries and the delete.

An import never holds the database's write lock for long (on SQLite every other writer waits
for it; issue 32: one transaction of 200,000 rows on 200,000 lines held it a minute):

1. the file is parsed and validated whole **before** any write (in a child process with the
   parse budget), and refused whole (422 naming the row and column) on one bad value; then
   checked against the caps ``TRACKVKF_ASSETS_IMPORT_MAX_ROWS`` (rows) and
   ``TRACKVKF_ASSETS_IMPORT_MAX_LINES`` (line and track pairs) — 413 naming ``file``;
2. its rows are written in batches of ``TRACKVKF_ASSETS_IMPORT_BATCH_ROWS``, one short
   transaction each, invisible to readers (an import in state ``writing``); on SQLite the
   importer pauses after each batch at least as long as it held the lock (and 0.1 s), so that
   waiting writers get their turn;
3. **one short transaction** points each of its (line, track) pairs at it, with its audit entry
   (``assets.import``): readers switch from the old assets to the new ones at that commit, all
   pairs at once;
4. the replaced rows are deleted in batches (set-based deletes, one short transaction each); a
   crash leaves only invisible rows, which the next import of the pair deletes (an import still
   ``writing`` after :data:`STALE_AFTER` is taken as abandoned).
"""

from __future__ import annotations

import datetime as dt
import time
from collections.abc import Callable
from typing import Any

from app.audit import record
from app.core.errors import ApiError
from app.core.i18n import _
from app.core.security import Actor
from app.db import assets_crud
from app.db.models import Asset, utcnow
from app.db.session import Database
from app.settings import Settings

__all__ = ["ImportResult", "import_assets", "parse_upload", "asset_dict", "find_assets", "remove_asset",
           "STALE_AFTER"]

#: an import still writing after this long is taken as abandoned (its writer died)
STALE_AFTER = dt.timedelta(hours=1)
#: the shortest pause of an importer after a batch on SQLite (the busy handler of a waiting writer
#: sleeps at most 0.1 s between its tries), s
_MIN_PAUSE_S = 0.1


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


class ImportResult(dict):
    """``imported``, ``replaced`` (the live assets of the same lines and tracks before), ``lines``."""


def _check_caps(settings: Settings, rows: list[dict[str, Any]], lines: dict) -> None:
    if len(rows) > settings.assets_import_max_rows:
        raise ApiError(413, "file", _("holds {n} assets, more than one import may write ({limit}, "
                                      "TRACKVKF_ASSETS_IMPORT_MAX_ROWS)", n=len(rows), limit=settings.assets_import_max_rows))
    if len(lines) > settings.assets_import_max_lines:
        raise ApiError(413, "file", _("holds assets of {n} lines and tracks, more than one import may replace ({limit}, "
                                      "TRACKVKF_ASSETS_IMPORT_MAX_LINES)", n=len(lines), limit=settings.assets_import_max_lines))


def import_assets(db: Database, settings: Settings, actor: Actor, data: bytes, filename: str | None, *,
                  sleep: Callable[[float], None] = time.sleep) -> ImportResult:
    """Import an asset file (CSV or GeoJSON): it replaces the assets of every line and track it holds.

    Parameters
    ----------
    db : Database
    settings : Settings
        The parse budget, the caps and the batch size (``TRACKVKF_ASSETS_IMPORT_*``).
    actor : Actor
        Who imports (audited ``assets.import`` in the commit that makes the assets live).
    data : bytes
        The file.
    filename : str or None
        Its name (CSV, or GeoJSON by ``.geojson``/``.json`` or content).
    sleep : callable
        The pause between batches (a test's clock).

    Returns
    -------
    ImportResult

    Raises
    ------
    RunFileError
        422 naming the row or feature and the column; nothing is written then.
    ApiError
        413 naming ``file`` beyond the caps.
    """
    rows = parse_upload(settings, data, filename)
    lines = assets_crud.lines_of(rows)
    _check_caps(settings, rows, lines)
    with db.write() as session:
        assets_crud.abandon_stale_imports(session, utcnow() - STALE_AFTER)
        import_id = assets_crud.start_import(session, actor.name, len(rows))
    with db.read() as session:  # what dead importers left (invisible rows) goes with this import's sweep
        left = {k: (0, 0.0) for k in assets_crud.abandoned_lines(session)}
    batch = settings.assets_import_batch_rows
    try:
        for i in range(0, len(rows), batch):
            t0 = time.monotonic()
            with db.write() as session:
                assets_crud.insert_rows(session, import_id, rows[i:i + batch])
            _pause(db, time.monotonic() - t0, sleep)
        with db.write() as session:
            replaced = assets_crud.switch_lines(session, import_id, lines)
            record(session, actor, "assets.import", target=filename,
                   detail={"imported": len(rows), "replaced": replaced, "lines": len(lines), "import_id": import_id})
    except BaseException:
        with db.write() as session:
            assets_crud.finish_import(session, import_id, "abandoned")
        _sweep(db, {**left, **lines}, batch, sleep)
        raise
    _sweep(db, {**left, **lines}, batch, sleep)
    return ImportResult(imported=len(rows), replaced=replaced, lines=len(lines))


def _pause(db: Database, held_s: float, sleep: Callable[[float], None]) -> None:
    """Let waiting writers have the lock (SQLite: one writer at a time; PostgreSQL: none to wait for)."""
    sleep(max(_MIN_PAUSE_S, held_s) if db.is_sqlite else 0.0)


def _sweep(db: Database, lines: dict, batch: int, sleep: Callable[[float], None]) -> None:
    """Delete the rows of ``lines`` no pointer names (replaced, abandoned), a batch a transaction."""
    for line_id, track in sorted(lines):
        while True:
            t0 = time.monotonic()
            with db.write() as session:
                n = assets_crud.delete_garbage(session, line_id, track, batch)
            if n < batch:
                break
            _pause(db, time.monotonic() - t0, sleep)


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


def remove_asset(db: Database, actor: Actor, asset_id: int) -> bool:
    """Delete one asset, audited ``assets.delete`` in the same transaction; whether it existed."""
    with db.write() as session:
        found = assets_crud.delete_asset(session, asset_id)
        if found:
            record(session, actor, "assets.delete", target=asset_id)
        return found
