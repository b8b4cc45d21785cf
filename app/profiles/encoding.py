"""How a profile answer is encoded: JSON in rows or columns (fixed decimals), its ETag, gzip, and
the request headers that decide what is sent (``If-None-Match``, ``Accept-Encoding``).

Bump :data:`ENCODING_VERSION` when the encoding of an answer changes: it is part of the
ETag, so browsers and caches fetch the new form.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import math

import numpy as np
import pandas as pd

__all__ = ["ENCODING_VERSION", "CACHE_CONTROL", "rows_json", "columns_json", "decimals", "etag", "matches",
           "accepts_gzip", "encoded"]

#: profile answers are immutable per published job: browsers keep them and revalidate (ETag)
CACHE_CONTROL = "private, no-cache"
#: bumped when the encoding of a profile answer changes (part of its ETag; 2: the answers of a job hold
#: ``sleeper_step`` and ``step_estimate_stored``, which a browser's copy of an earlier answer lacks)
ENCODING_VERSION = 2
#: km columns keep 6 decimals (1 mm); other columns 5 significant digits of their largest value
_KM_COLUMNS = frozenset({"km", "km_from", "km_to"})
_KM_DECIMALS = 6
_SIGNIFICANT = 5
_GZIP_MIN_BYTES = 1024
_GZIP_LEVEL = 1  # 0.7 ms for a map's 87 kB (level 5: 2.4 ms, 10 % fewer bytes)


def rows_json(head: dict, df: pd.DataFrame) -> bytes:
    """``layout=rows``: the rows as objects, serialised by pandas (fast, NaN -> null)."""
    values = df.replace([np.inf, -np.inf], np.nan)
    rows = values.to_json(orient="records", double_precision=15) if len(df) else "[]"
    return (json.dumps(head)[:-1] + ', "rows": ' + rows + "}").encode()


def decimals(name: str, values: pd.Series) -> int:
    """Fixed decimals of a float column: 6 for km, else 5 significant digits of its largest value."""
    if name in _KM_COLUMNS:
        return _KM_DECIMALS
    finite = np.abs(values.to_numpy(dtype=np.float64, na_value=np.nan))
    finite = finite[np.isfinite(finite) & (finite > 0)]
    if not len(finite):
        return _SIGNIFICANT
    return int(min(max(_SIGNIFICANT - 1 - math.floor(math.log10(float(finite.max()))), 0), 15))


def columns_json(head: dict, df: pd.DataFrame) -> bytes:
    """``layout=columns``: one array per column (the wheel is in the head), fixed decimals."""
    parts = []
    names = [c for c in df.columns if c != "wheel"]
    for name in names:
        col = df[name]
        if pd.api.types.is_float_dtype(col.dtype):
            if np.isinf(col.to_numpy()).any():
                col = col.replace([np.inf, -np.inf], np.nan)
            text = col.to_json(orient="values", double_precision=decimals(name, col))
        elif pd.api.types.is_numeric_dtype(col.dtype) or pd.api.types.is_bool_dtype(col.dtype):
            text = col.to_json(orient="values")
        else:
            text = json.dumps(col.astype(object).where(col.notna(), None).tolist())
        parts.append(f"{json.dumps(name)}: {text}")
    head = {**head, "columns": names}
    return (json.dumps(head)[:-1] + ', "data": {' + ", ".join(parts) + "}}").encode()


def etag(job_id: int, settings_rows: int, **query: object) -> str:
    """ETag of a profile answer: the job (immutable once published) and the normalised query.

    Weak (``W/``): the same answer is sent plain or gzip-encoded.
    """
    key = json.dumps({"v": ENCODING_VERSION, "job": job_id, "max_rows": settings_rows, **query}, sort_keys=True)
    return 'W/"pf-' + hashlib.sha256(key.encode()).hexdigest()[:32] + '"'


def matches(etag: str, if_none_match: str | None) -> bool:
    """Whether an ``If-None-Match`` header names ``etag`` or ``*`` (weak comparison, RFC 9110)."""
    if not if_none_match:
        return False
    tags = [t.strip().removeprefix("W/") for t in if_none_match.split(",")]
    return "*" in tags or etag.removeprefix("W/") in tags


def accepts_gzip(accept: str) -> bool:
    """Whether an ``Accept-Encoding`` header value accepts gzip (``q=0`` refuses it)."""
    for part in accept.split(","):
        name, _, params = part.strip().partition(";")
        if name.strip().lower() in ("gzip", "*"):
            return params.replace(" ", "").lower() not in ("q=0", "q=0.0", "q=0.00", "q=0.000")
    return False


def encoded(body: bytes) -> tuple[bytes, bytes | None]:
    """The body and, when worth it, its gzip encoding (kept together in the answer cache)."""
    return body, gzip.compress(body, _GZIP_LEVEL, mtime=0) if len(body) >= _GZIP_MIN_BYTES else None
