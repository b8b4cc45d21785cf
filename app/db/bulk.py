"""Bulk inserts of numeric frames: binary ``COPY`` on PostgreSQL, ``executemany`` on SQLite.

The result writers store hundreds of thousands of rows at a time (a run's
profile rows, its segment condition rows). :func:`insert_frame` writes a
DataFrame whose columns are the table's, in the caller's transaction: on
PostgreSQL with psycopg 3 as a binary ``COPY`` stream laid out by numpy
(:mod:`app.db.pg_copy`), on SQLite as one plain ``executemany`` (3–4x faster
than SQLAlchemy Core), elsewhere through Core in batches. NaN becomes NULL.
"""

from __future__ import annotations

from typing import Any

import pandas as pd
from sqlalchemy import Table, insert
from sqlalchemy.orm import Session

from app.core.jsonable import finite_list
from app.db.pg_copy import binary_copy_stream

__all__ = ["insert_frame", "frame_columns"]

_CORE_BATCH = 20_000


def frame_columns(frame: pd.DataFrame) -> dict[str, list[Any]]:
    """Column lists of a numeric/text frame, NaN as None (Python values for a DBAPI)."""
    data: dict[str, list[Any]] = {}
    for col in frame.columns:
        values = frame[col].to_numpy()
        if values.dtype.kind == "f":
            data[col] = finite_list(values)
        else:
            data[col] = values.tolist()
    return data


def insert_frame(session: Session, table: Table, frame: pd.DataFrame, pg_types: dict[str, str]) -> None:
    """Insert the rows of ``frame`` (columns named as the table's) into ``table``.

    Parameters
    ----------
    session : Session
        The transaction to write in.
    table : Table
        Target table.
    frame : pandas.DataFrame
        One row per table row; float NaN/inf become NULL.
    pg_types : dict
        PostgreSQL binary type of every column of ``frame``
        (:data:`app.db.pg_copy.PG_BINARY_TYPES`).
    """
    names = list(frame.columns)
    if not len(frame):
        return
    dialect = session.get_bind().dialect.name
    if dialect == "postgresql":
        dbapi = session.connection().connection.dbapi_connection
        with dbapi.cursor() as cursor:
            if hasattr(cursor, "copy"):  # psycopg 3; same connection and transaction
                stream = binary_copy_stream([(frame[c].to_numpy(), pg_types[c]) for c in names])
                quoted = ", ".join(f'"{c}"' for c in names)
                with cursor.copy(f"COPY {table.name} ({quoted}) FROM STDIN (FORMAT BINARY)") as copy:
                    copy.write(stream)
                return
    data = frame_columns(frame)
    rows = zip(*data.values(), strict=True)
    if dialect == "sqlite":
        quoted = ", ".join(f'"{c}"' for c in names)
        sql = f"INSERT INTO {table.name} ({quoted}) VALUES ({', '.join('?' * len(names))})"
        session.connection().exec_driver_sql(sql, list(rows))
        return
    batch: list[dict[str, Any]] = []
    for row in rows:
        batch.append(dict(zip(names, row, strict=True)))
        if len(batch) == _CORE_BATCH:
            session.execute(insert(table), batch)
            batch = []
    if batch:
        session.execute(insert(table), batch)
