"""Numeric query results straight into numpy: no Python row object per row."""

from __future__ import annotations

import numpy as np
from sqlalchemy import Select
from sqlalchemy.orm import Session

__all__ = ["fetch_numeric"]


def fetch_numeric(session: Session, stmt: Select, n_columns: int) -> np.ndarray:
    """The rows of a query of ``n_columns`` numeric columns as one float array (NULL -> NaN).

    Straight from the DBAPI cursor: the tuples need no row processing for numbers.
    """
    result = session.connection().execute(stmt)
    try:
        rows = result.cursor.fetchall()
    finally:
        result.close()
    return np.array(rows, dtype=np.float64).reshape(len(rows), n_columns)
