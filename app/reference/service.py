"""Reference data: an import validated as a whole, then written in one transaction with its audit
entry (``mode="replace"`` first deletes the stored rows of the lines and tracks in the file, and
asks for ``confirm`` where such a line already has runs); a delete of a line's rows; the lists of a
line, track and km window."""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal

from sqlalchemy.orm import Session

from app.audit import record
from app.core.errors import ApiError
from app.core.i18n import _
from app.core.security import Actor
from app.db import reference_crud
from app.db.session import Database
from app.io.isolation import read_reference_upload
from app.settings import Settings

__all__ = ["Kind", "import_reference", "delete_reference", "reference_window"]

#: The kinds of reference data.
Kind = Literal["subsidence", "maintenance", "superstructure"]


def import_reference(db: Database, settings: Settings, actor: Actor, kind: Kind, data: bytes, *,
                     fmt: Literal["csv", "parquet"] | None, filename: str | None,
                     mode: Literal["append", "replace"] = "append", confirm: bool = False) -> tuple[int, int]:
    """Validate a CSV or Parquet file of ``kind``, then store all its rows (audited
    ``reference.import``): how many rows were imported and how many stored ones replaced.

    The file is parsed in a child process with a time and memory budget
    (:func:`app.io.isolation.read_reference_upload`). ``mode="replace"`` over a line and track
    that has runs needs ``confirm``: the results of those runs (stiffness index, places, section
    classes) were found on the rows it deletes.

    Raises
    ------
    RunFileError
        422 naming the row (1 = first data row) and the column; nothing is imported then.
    ApiError
        409 naming ``confirm`` (the line, track and how many runs it has) for a replace over a
        line with runs without ``confirm``; nothing is changed then.
    """
    rows = read_reference_upload(settings, data, kind, fmt, filename)
    with db.write() as session:
        replaced = 0
        if mode == "replace":
            if not confirm:
                _refuse_replace_over_runs(session, kind, {(r["line_id"], r["track"]) for r in rows})
            for line_id, track in sorted({(r["line_id"], r["track"]) for r in rows}):
                replaced += reference_crud.delete_reference(session, kind, line_id, track)
        imported = reference_crud.insert_reference(session, kind, rows)
        record(session, actor, "reference.import", target=kind,
               detail={"imported": imported, "replaced": replaced, "mode": mode, "filename": filename})
    return imported, replaced


def _refuse_replace_over_runs(session: Session, kind: Kind, pairs: set[tuple[str, str]]) -> None:
    """409 naming ``confirm`` when a line and track of ``pairs`` has runs (the first such, in order)."""
    with_runs = reference_crud.runs_per_line(session, sorted(pairs))
    if not with_runs:
        return
    (line, track), n = min(with_runs.items())
    others = len(with_runs) - 1
    message = _("line {line} track {track} has {n} run(s) already: mode=replace deletes its stored {kind} rows, "
                "on which their results were found; send confirm=true to replace them", line=line, track=track,
                n=n, kind=kind)
    if others:
        message = _("{first} (and {others} more line(s) of the file with runs)", first=message, others=others)
    raise ApiError(409, "confirm", message)


def delete_reference(db: Database, actor: Actor, kind: Kind, line_id: str, track: str | None = None) -> int:
    """Delete the rows of ``kind`` of a line (and track), audited ``reference.delete``; how many."""
    with db.write() as session:
        n = reference_crud.delete_reference(session, kind, line_id, track)
        record(session, actor, "reference.delete", target=kind,
               detail={"line_id": line_id, "track": track, "deleted": n})
    return n


def reference_window(db: Database, kind: Kind, *, limit: int, line_id: str | None = None,
                     track: str | None = None, km_from: float | None = None, km_to: float | None = None,
                     types: list[str] | None = None, since: dt.date | None = None) -> dict[str, Any]:
    """The rows of ``kind`` in a line, track and km window (maintenance also by ``types`` and
    ``since``): ``items``, at most ``limit`` of them, and whether there were more (``truncated``)."""
    query: dict[str, Any] = {"line_id": line_id, "track": track, "km_from": km_from, "km_to": km_to}
    if kind == "maintenance":
        query.update(types=types, since=since)
    with db.read() as session:
        rows = reference_crud.reference_records(session, kind, limit=limit + 1, **query)
    return {"items": rows[:limit], "truncated": len(rows) > limit}
