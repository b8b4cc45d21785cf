"""The bound of every row id, named once."""

from __future__ import annotations

__all__ = ["MAX_ID"]

#: Largest id of a row (32-bit integer keys; PostgreSQL ``integer``): every id a client gives (path, query,
#: form field, list of ids) is refused above it before it reaches a query.
MAX_ID = 2**31 - 1
