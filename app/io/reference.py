"""Reference data files (CSV or Parquet) → validated rows.

Kinds and columns (aliases in brackets; extra columns are ignored):

``subsidence``
    line_id [line], track, km, subsidence_mm [subsidence], date; optional
    rail (1/right, 2/left; empty = both rails).
``maintenance``
    line_id [line], track, km_from, km_to, type, date. Types: tamping,
    grinding, rail_replacement, ballast_cleaning, other (case and
    spaces/hyphens are normalised: "Rail replacement" → rail_replacement).
``superstructure``
    line_id [line], track, km_from, km_to, type, details (optional, free text).

Dates are ISO (``yyyy-mm-dd``; a datetime keeps its date). ``km_to`` must not
be below ``km_from``. Errors raise :class:`RunFileError` whose field names the
row (1 = first data row) and the column, so nothing is half-imported.
"""

from __future__ import annotations

import io
import math
from typing import Any, Literal

import numpy as np
import pandas as pd

from app.core.i18n import _
from app.io.errors import RunFileError

__all__ = ["REFERENCE_KINDS", "MAINTENANCE_TYPES", "read_reference"]

REFERENCE_KINDS: tuple[str, ...] = ("subsidence", "maintenance", "superstructure")
MAINTENANCE_TYPES: tuple[str, ...] = ("tamping", "grinding", "rail_replacement", "ballast_cleaning", "other")
_ALIASES = {"line": "line_id", "subsidence": "subsidence_mm"}
_REQUIRED = {
    "subsidence": ("line_id", "track", "km", "subsidence_mm", "date"),
    "maintenance": ("line_id", "track", "km_from", "km_to", "type", "date"),
    "superstructure": ("line_id", "track", "km_from", "km_to", "type"),
}
_OPTIONAL = {"subsidence": ("rail",), "maintenance": (), "superstructure": ("details",)}
_MAX_TEXT = {"line_id": 128, "track": 64, "type": 64, "details": 2000}
_KM_BOUND = 100_000.0


def _fail(row: int | None, column: str, message: str) -> RunFileError:
    where = f"row {row}, column {column}" if row is not None else f"column {column}"
    return RunFileError(where, message)


def _load(data: bytes, fmt: str) -> pd.DataFrame:
    try:
        if fmt == "csv":
            return pd.read_csv(io.BytesIO(data), dtype=str, keep_default_na=False, skipinitialspace=True)
        return pd.read_parquet(io.BytesIO(data))
    except Exception as exc:  # noqa: BLE001 - any parser error is the file's fault
        raise RunFileError("file", _("cannot read the file as {fmt}: {error}", fmt=fmt, error=exc)) from None


def _text(df: pd.DataFrame, col: str, required: bool = True) -> np.ndarray:
    vals = df[col].to_numpy(dtype=object)
    out = np.empty(vals.size, dtype=object)
    for i, v in enumerate(vals):
        s = "" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v).strip()
        if isinstance(v, float) and v.is_integer() and col in ("line_id", "track"):
            s = str(int(v))
        if required and not s:
            raise _fail(i + 1, col, _("is empty"))
        if len(s) > _MAX_TEXT.get(col, 128):
            raise _fail(i + 1, col, _("is longer than {n} characters", n=_MAX_TEXT.get(col, 128)))
        if "\x00" in s:
            raise _fail(i + 1, col, _("must not contain NUL characters (\\u0000)"))
        out[i] = s or None
    return out


def _number(df: pd.DataFrame, col: str, bound: float | None = _KM_BOUND) -> np.ndarray:
    raw = df[col]
    num = pd.to_numeric(raw.map(lambda v: v.strip() if isinstance(v, str) else v), errors="coerce")
    vals = num.to_numpy(dtype=np.float64, na_value=np.nan)
    bad = ~np.isfinite(vals)
    if bound is not None:
        bad |= np.abs(np.nan_to_num(vals)) > bound
    if bad.any():
        i = int(np.argmax(bad))
        shown = raw.iloc[i]
        raise _fail(i + 1, col, _("{value!r} is not a finite number", value=shown) if not np.isfinite(vals[i])
                    else _("{value!r} is outside ±{bound:g}", value=shown, bound=bound))
    return vals


def _dates(df: pd.DataFrame, col: str) -> list:
    out = []
    for i, v in enumerate(df[col].to_numpy(dtype=object)):
        try:
            if v is None or (isinstance(v, float) and math.isnan(v)) or (isinstance(v, str) and not v.strip()):
                raise ValueError("empty")
            ts = pd.Timestamp(v.strip() if isinstance(v, str) else v)
            if pd.isna(ts) or not 1800 <= ts.year <= 2200:
                raise ValueError("out of range")
        except (ValueError, TypeError):
            raise _fail(i + 1, col, _("{value!r} is not an ISO date (yyyy-mm-dd)", value=v)) from None
        out.append(ts.date())
    return out


def _maintenance_type(values: np.ndarray) -> np.ndarray:
    out = np.empty(values.size, dtype=object)
    for i, v in enumerate(values):
        t = str(v).strip().lower().replace(" ", "_").replace("-", "_")
        if t not in MAINTENANCE_TYPES:
            raise _fail(i + 1, "type", _("{value!r} is not one of {choices}", value=v, choices=", ".join(MAINTENANCE_TYPES)))
        out[i] = t
    return out


def _rail(df: pd.DataFrame) -> list[int | None]:
    out: list[int | None] = []
    names = {"1": 1, "1.0": 1, "right": 1, "r": 1, "2": 2, "2.0": 2, "left": 2, "l": 2, "": None,
             "none": None, "nan": None, "both": None}
    for i, v in enumerate(df["rail"].to_numpy(dtype=object)):
        key = "" if v is None else str(v).strip().lower()
        if key not in names:
            raise _fail(i + 1, "rail", _("{value!r} is not 1 (right), 2 (left) or empty (both rails)", value=v))
        out.append(names[key])
    return out


def read_reference(
    data: bytes, kind: str, fmt: Literal["csv", "parquet"] | None = None, filename: str | None = None
) -> list[dict[str, Any]]:
    """Parse and validate a reference file.

    Parameters
    ----------
    data : bytes
        The file content.
    kind : {"subsidence", "maintenance", "superstructure"}
        What the file holds.
    fmt : {"csv", "parquet"}, optional
        File format; default from ``filename``'s extension, else the Parquet
        magic bytes, else CSV.
    filename : str, optional
        Original file name.

    Returns
    -------
    list of dict
        One dict per row with the columns of the kind (dates as ``datetime.date``).

    Raises
    ------
    RunFileError
        ``field`` names the row and column (or ``file``, ``format``).
    """
    if kind not in REFERENCE_KINDS:
        raise RunFileError("kind", _("must be one of {items}, got {kind!r}", items=', '.join(REFERENCE_KINDS), kind=kind))
    if fmt is None:
        name = (filename or "").lower()
        if name.endswith((".parquet", ".pq")) or data[:4] == b"PAR1":
            fmt = "parquet"
        else:
            fmt = "csv"
    if fmt not in ("csv", "parquet"):
        raise RunFileError("format", _("must be csv or parquet, got {fmt!r}", fmt=fmt))
    if not data:
        raise RunFileError("file", _("is empty"))
    df = _load(data, fmt)
    df = df.rename(columns={c: _ALIASES.get(str(c).strip().lower(), str(c).strip().lower()) for c in df.columns})
    missing = [c for c in _REQUIRED[kind] if c not in df.columns]
    if missing:
        raise _fail(None, missing[0], _("is missing (columns needed: {columns})", columns=", ".join(_REQUIRED[kind])))
    if len(df) == 0:
        raise RunFileError("file", _("has no data rows"))
    cols: dict[str, Any] = {"line_id": _text(df, "line_id"), "track": _text(df, "track")}
    if kind == "subsidence":
        cols["km"] = _number(df, "km")
        cols["subsidence_mm"] = _number(df, "subsidence_mm", bound=10_000.0)
        cols["rail"] = _rail(df) if "rail" in df.columns else [None] * len(df)
    else:
        cols["km_from"] = _number(df, "km_from")
        cols["km_to"] = _number(df, "km_to")
        rev = cols["km_to"] < cols["km_from"]
        if rev.any():
            i = int(np.argmax(rev))
            raise _fail(i + 1, "km_to", _("{km_to:g} is below km_from {km_from:g}", km_to=cols["km_to"][i], km_from=cols["km_from"][i]))
        if kind == "maintenance":
            cols["type"] = _maintenance_type(_text(df, "type"))
        else:
            cols["type"] = _text(df, "type")
            cols["details"] = _text(df, "details", required=False) if "details" in df.columns else [None] * len(df)
    if kind != "superstructure":
        cols["date"] = _dates(df, "date")
    names = list(cols)
    out = []
    for values in zip(*cols.values(), strict=True):
        row = dict(zip(names, values, strict=True))
        for k, v in row.items():
            if isinstance(v, np.floating):
                row[k] = float(v)
        out.append(row)
    return out
