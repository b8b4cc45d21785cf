"""Binary COPY streams (app/db/pg_copy.py): against an independent struct decoder,
and through a real PostgreSQL server (round trip, and byte equality with the server's
own binary COPY output)."""

from __future__ import annotations

import math
import struct
from collections import Counter

import numpy as np
import pytest

from app.db.pg_copy import binary_copy_stream

_UNPACK = {"int2": ">h", "int4": ">i", "int8": ">q", "float8": ">d"}


def _decode(stream: bytes, types: list[str]) -> list[tuple]:
    """Slow reference: read the stream field by field with struct (NULL -> None)."""
    assert stream[:11] == b"PGCOPY\n\xff\r\n\x00"
    flags, ext = struct.unpack(">ii", stream[11:19])
    assert flags == 0 and ext == 0
    at, rows = 19, []
    while True:
        (count,) = struct.unpack(">h", stream[at : at + 2])
        at += 2
        if count == -1:
            assert at == len(stream)
            return rows
        assert count == len(types)
        row = []
        for t in types:
            (size,) = struct.unpack(">i", stream[at : at + 4])
            at += 4
            if size == -1:
                row.append(None)
                continue
            raw = stream[at : at + size]
            at += size
            row.append(raw.decode() if t == "text" else struct.unpack(_UNPACK[t], raw)[0])
        rows.append(tuple(row))


def _columns(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    floats = rng.normal(size=n) * 10.0 ** rng.integers(-300, 300, n)
    floats[rng.random(n) < 0.2] = np.nan
    floats[: min(n, 2)] = [np.inf, -np.inf][: min(n, 2)]
    words = np.array(rng.choice(["11", "42", "", "Zürich", "a\tb\\N"], n), dtype=object)
    words[rng.random(n) < 0.1] = None
    return [
        (np.full(n, 7, dtype=np.int64), "int4"),
        (words, "text"),
        (rng.integers(-(2**62), 2**62, n), "int8"),
        (floats, "float8"),
        (rng.integers(-30000, 30000, n).astype(np.int16), "int2"),
    ]


def _expected(columns) -> list[tuple]:
    out = []
    for i in range(len(columns[0][0])):
        row = []
        for values, t in columns:
            v = values[i]
            if t == "float8":
                row.append(float(v) if math.isfinite(v) else None)
            elif t == "text":
                row.append(v)
            else:
                row.append(int(v))
        out.append(tuple(row))
    return out


@pytest.mark.parametrize("n", [0, 1, 2, 37, 2000])
def test_stream_decodes_to_the_input(n):
    cols = _columns(n, seed=n)
    got = _decode(binary_copy_stream(cols), [t for _, t in cols])
    # rows are grouped by layout (NULL fields, text lengths): the same rows, in another order
    assert Counter(got) == Counter(_expected(cols)) and len(got) == n


def test_rows_of_one_layout_keep_their_order():
    rng = np.random.default_rng(9)
    cols = [(np.arange(500), "int8"), (rng.normal(size=500), "float8"),
            (np.array(["11", "42"] * 250, dtype=object), "text")]
    assert _decode(binary_copy_stream(cols), ["int8", "float8", "text"]) == _expected(cols)
    cols[1][0][7] = np.nan  # a second layout: its row comes after the first layout's rows
    got = _decode(binary_copy_stream(cols), ["int8", "float8", "text"])
    assert [r[0] for r in got] == [i for i in range(500) if i != 7] + [7] and got[-1][1] is None


def test_empty_texts():
    cols = [(np.array(["", "ab", "", None], dtype=object), "text"), (np.arange(4), "int4")]
    assert Counter(_decode(binary_copy_stream(cols), ["text", "int4"])) == Counter(_expected(cols))


def test_rejects_bad_columns():
    with pytest.raises(ValueError, match="at least one column"):
        binary_copy_stream([])
    with pytest.raises(ValueError, match=r"columns\[1\]: expected 3 values"):
        binary_copy_stream([(np.arange(3), "int4"), (np.arange(2), "int4")])
    with pytest.raises(ValueError, match="unknown type 'numeric'"):
        binary_copy_stream([(np.arange(3), "numeric")])
    with pytest.raises(ValueError, match="needs integers"):
        binary_copy_stream([(np.array([1.5]), "int8")])
    with pytest.raises(ValueError, match="outside the range of int2"):
        binary_copy_stream([(np.array([40000]), "int2")])


def test_postgresql_reads_the_stream_and_writes_the_same_bytes(pg_cluster):
    if isinstance(pg_cluster, str):
        pytest.skip(pg_cluster)
    import psycopg

    url = pg_cluster.create_database().replace("postgresql+psycopg", "postgresql")
    cols = _columns(500, seed=3)
    expected = _expected(cols)
    with psycopg.connect(url) as conn:
        conn.execute("CREATE TEMP TABLE t (a int4, w varchar(8), b int8, x float8, s int2)")
        with conn.cursor().copy("COPY t FROM STDIN (FORMAT BINARY)") as copy:
            copy.write(binary_copy_stream(cols))
        got = conn.execute("SELECT a, w, b, x, s FROM t").fetchall()
        assert Counter(tuple(r) for r in got) == Counter(expected)
        # byte for byte what the server itself writes for the same rows
        with conn.cursor().copy("COPY (SELECT a, w, b, x, s FROM t) TO STDOUT (FORMAT BINARY)") as copy:
            dumped = b"".join(bytes(block) for block in copy)
        assert dumped == binary_copy_stream(cols)
