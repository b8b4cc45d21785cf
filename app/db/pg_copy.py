"""PostgreSQL binary ``COPY`` streams built column-wise with numpy.

Storing a long run writes about a million profile rows. Formatting them as
COPY text costs ~35 µs a row in pandas, and psycopg's ``write_row`` ~5 µs a
row in Python; :func:`binary_copy_stream` lays the same rows out in
PostgreSQL's binary COPY format with a few vectorised scatters per column
(well under 1 µs a row), and NULLs (NaN / None) make no difference.

Format (PostgreSQL manual, "COPY — Binary Format"): an 11-byte signature,
a 32-bit flags word and a 32-bit header-extension length; then per row a
16-bit field count and per field a 32-bit byte length (−1 for NULL) followed
by the value in network byte order; then a 16-bit −1 trailer.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["PG_BINARY_TYPES", "binary_copy_stream"]

_SIGNATURE = b"PGCOPY\n\xff\r\n\x00"
_HEADER = _SIGNATURE + np.array([0, 0], dtype=">i4").tobytes()
_TRAILER = np.array([-1], dtype=">i2").tobytes()

#: PostgreSQL type name -> big-endian numpy dtype of its binary value (None: text bytes)
PG_BINARY_TYPES: dict[str, str | None] = {
    "int2": ">i2",
    "int4": ">i4",
    "int8": ">i8",
    "float8": ">f8",
    "text": None,  # also varchar / char: their binary form is the UTF-8 bytes
}


def _scatter(buf: np.ndarray, at: np.ndarray, data: np.ndarray) -> None:
    """``buf[at[i] + j] = data[i, j]`` for every row ``i`` and byte ``j``."""
    if at.size:
        buf[at[:, None] + np.arange(data.shape[1])] = data


def _text_column(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(null mask, byte length per row, concatenated UTF-8 bytes) of a text column."""
    null = np.array([v is None for v in values], dtype=bool)
    encoded = [b"" if v is None else str(v).encode("utf-8") for v in values]
    lengths = np.fromiter((len(e) for e in encoded), dtype=np.int64, count=len(encoded))
    return null, lengths, np.frombuffer(b"".join(encoded), dtype=np.uint8)


def binary_copy_stream(columns: Sequence[tuple[np.ndarray, str]]) -> bytes:
    """One ``COPY … FROM STDIN (FORMAT BINARY)`` stream of the given columns.

    Parameters
    ----------
    columns : sequence of (array_like, str)
        One ``(values, pg_type)`` per table column, in the order of the
        ``COPY`` column list; all of one length. ``pg_type`` is a key of
        :data:`PG_BINARY_TYPES`. Float NaN / ±inf and ``None`` of a text
        column are written as NULL; integer columns have no NULL.

    Returns
    -------
    bytes
        Header, rows and trailer: pass to psycopg's ``Copy.write``.

    Raises
    ------
    ValueError
        If there are no columns, the lengths differ, a type is unknown, an
        integer column holds non-integers or values out of its type's range.
    """
    if not columns:
        raise ValueError("columns: at least one column is needed")
    if len(columns) > 1600:
        raise ValueError(f"columns: PostgreSQL tables have at most 1600 columns, got {len(columns)}")
    n = len(columns[0][0])
    prepared = []
    for i, (values, pg_type) in enumerate(columns):
        if pg_type not in PG_BINARY_TYPES:
            raise ValueError(f"columns[{i}]: unknown type {pg_type!r} (known: {', '.join(PG_BINARY_TYPES)})")
        arr = np.asarray(values, dtype=object if PG_BINARY_TYPES[pg_type] is None else None)
        if arr.ndim != 1 or arr.shape[0] != n:
            raise ValueError(f"columns[{i}]: expected {n} values in one dimension, got shape {arr.shape}")
        dtype = PG_BINARY_TYPES[pg_type]
        if dtype is None:
            null, lengths, data = _text_column(arr)
            prepared.append((null, lengths, data, None))
        elif np.dtype(dtype).kind == "f":
            vals = arr.astype(np.float64)
            null = ~np.isfinite(vals)
            prepared.append((null, np.full(n, 8, dtype=np.int64), vals.astype(dtype), dtype))
        else:
            if arr.dtype.kind not in "iub":
                raise ValueError(f"columns[{i}]: {pg_type} needs integers, got dtype {arr.dtype}")
            info = np.iinfo(np.dtype(dtype))
            if n and (arr.min() < info.min or arr.max() > info.max):
                raise ValueError(f"columns[{i}]: values outside the range of {pg_type}")
            size = np.dtype(dtype).itemsize
            prepared.append((np.zeros(n, dtype=bool), np.full(n, size, dtype=np.int64), arr.astype(dtype), dtype))

    # byte size of every row: field count + per field (length word + value unless NULL)
    row_size = np.full(n, 2, dtype=np.int64)
    for null, lengths, _, _ in prepared:
        row_size += 4 + np.where(null, 0, lengths)
    starts = len(_HEADER) + np.concatenate(([0], np.cumsum(row_size)[:-1])) if n else np.zeros(0, np.int64)
    total = len(_HEADER) + int(row_size.sum()) + len(_TRAILER)
    buf = np.empty(total, dtype=np.uint8)
    buf[: len(_HEADER)] = np.frombuffer(_HEADER, dtype=np.uint8)
    buf[total - len(_TRAILER) :] = np.frombuffer(_TRAILER, dtype=np.uint8)
    _scatter(buf, starts, np.full((n, 1), len(columns), dtype=">i2").view(np.uint8).reshape(n, 2))

    pos = starts + 2
    for null, lengths, data, dtype in prepared:
        length_word = np.where(null, -1, lengths).astype(">i4").view(np.uint8).reshape(n, 4)
        _scatter(buf, pos, length_word)
        ok = ~null
        if dtype is not None:
            width = np.dtype(dtype).itemsize
            _scatter(buf, pos[ok] + 4, data.view(np.uint8).reshape(n, width)[ok])
        elif data.size:
            # variable-length text: byte j of row i goes to pos[i] + 4 + j
            lens = lengths[ok]
            first = np.concatenate(([0], np.cumsum(lens)[:-1]))
            within = np.arange(data.size) - np.repeat(first, lens)
            buf[np.repeat(pos[ok] + 4, lens) + within] = data
        pos = pos + 4 + np.where(null, 0, lengths)
    return buf.tobytes()
