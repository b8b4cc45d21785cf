"""Queries and changes of the reference data (subsidence, maintenance, superstructure).

Every function takes an open session; the caller decides the transaction.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
from sqlalchemy import and_, delete, func, insert, select, tuple_
from sqlalchemy.orm import Session

from app.db.models import (
    MaintenanceAction,
    Run,
    SubsidenceMeasurement,
    SuperstructureSection,
    utcnow,
)

__all__ = ["MODELS", "insert_reference", "delete_reference", "reference_frame", "reference_records",
           "runs_per_line"]

MODELS = {
    "subsidence": SubsidenceMeasurement,
    "maintenance": MaintenanceAction,
    "superstructure": SuperstructureSection,
}
_COLUMNS = {
    "subsidence": ("id", "line_id", "track", "km", "rail", "subsidence_mm", "date"),
    "maintenance": ("id", "line_id", "track", "km_from", "km_to", "type", "date"),
    "superstructure": ("id", "line_id", "track", "km_from", "km_to", "type", "details"),
}
_BATCH = 20_000


def insert_reference(session: Session, kind: str, rows: Sequence[dict[str, Any]], *, replace: bool = False) -> int:
    """Insert validated rows of ``kind``; with ``replace`` first delete the stored rows of
    the (line_id, track) pairs present in ``rows``. Returns the number inserted."""
    model = MODELS[kind]
    if replace:
        pairs = sorted({(r["line_id"], r["track"]) for r in rows})
        for i in range(0, len(pairs), 500):
            session.execute(delete(model).where(tuple_(model.line_id, model.track).in_(pairs[i:i + 500])))
    now = utcnow()
    batch = []
    for r in rows:
        batch.append({**r, "imported_at": now})
        if len(batch) == _BATCH:
            session.execute(insert(model), batch)
            batch = []
    if batch:
        session.execute(insert(model), batch)
    return len(rows)


def runs_per_line(session: Session, pairs: Sequence[tuple[str, str]]) -> dict[tuple[str, str], int]:
    """How many runs each (line_id, track) of ``pairs`` has; pairs without runs are left out."""
    out: dict[tuple[str, str], int] = {}
    pairs = sorted(set(pairs))
    for i in range(0, len(pairs), 500):
        stmt = (select(Run.line_id, Run.track, func.count()).where(tuple_(Run.line_id, Run.track).in_(pairs[i:i + 500]))
                .group_by(Run.line_id, Run.track))
        out.update({(line, track): int(n) for line, track, n in session.execute(stmt)})
    return out


def delete_reference(session: Session, kind: str, line_id: str, track: str | None = None) -> int:
    """Delete the rows of ``kind`` of a line (and track). Returns the number deleted."""
    model = MODELS[kind]
    cond = [model.line_id == line_id]
    if track is not None:
        cond.append(model.track == track)
    return int(session.execute(delete(model).where(and_(*cond))).rowcount or 0)


def reference_frame(
    session: Session,
    kind: str,
    *,
    line_id: str | None = None,
    track: str | None = None,
    km_from: float | None = None,
    km_to: float | None = None,
    types: Sequence[str] | None = None,
    since: dt.date | None = None,
    limit: int | None = None,
) -> pd.DataFrame:
    """Rows of ``kind`` as a DataFrame (ordered along the km axis).

    ``km_from``/``km_to`` keep points inside (subsidence) or intervals
    overlapping (maintenance, superstructure) the range; ``types`` and
    ``since`` (inclusive) filter maintenance and superstructure.
    """
    model = MODELS[kind]
    cols = _COLUMNS[kind]
    cond = []
    if line_id is not None:
        cond.append(model.line_id == line_id)
    if track is not None:
        cond.append(model.track == track)
    if kind == "subsidence":
        if km_from is not None:
            cond.append(model.km >= km_from)
        if km_to is not None:
            cond.append(model.km <= km_to)
        order = (model.km, model.id)
    else:
        if km_from is not None:
            cond.append(model.km_to >= km_from)
        if km_to is not None:
            cond.append(model.km_from <= km_to)
        order = (model.km_from, model.id)
    if types:
        cond.append(model.type.in_(list(types)))
    if since is not None and kind != "superstructure":
        cond.append(model.date >= since)
    stmt = select(*[getattr(model, c) for c in cols]).where(and_(True, *cond)).order_by(*order)
    if limit is not None:
        stmt = stmt.limit(limit)
    rows = session.connection().execute(stmt).all()
    return pd.DataFrame([tuple(r) for r in rows], columns=list(cols))


def reference_records(session: Session, kind: str, **query: Any) -> list[dict[str, Any]]:
    """Rows of ``kind`` (:func:`reference_frame`'s filters and ``limit``) as plain records: a
    missing value None, the rail (superstructure) an int."""
    out = reference_frame(session, kind, **query).replace({np.nan: None}).to_dict(orient="records")
    for r in out:
        if "rail" in r and r["rail"] is not None:
            r["rail"] = int(r["rail"])
    return out
