"""Values made valid JSON: numpy scalars and arrays to Python, NaN and ±inf to None, times as ISO 8601.

The one place of these rules: wherever results leave numpy for JSON (the job's
metadata and wheel rows in SQL, chunk records of the fan-out worker, the files the
CLI writes, the API's answers) a non-finite number becomes ``null``
(:func:`jsonable` for structures, :func:`finite_or_none` for one number,
:func:`finite_list` for an array) and a time carries its UTC offset (:func:`iso_time`).
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

import numpy as np

__all__ = ["jsonable", "finite_or_none", "finite_list", "iso_time"]


def _scalar(value: Any) -> Any:
    """A scalar as a Python value; a non-finite float as None."""
    if value is None:
        return None
    if isinstance(value, float | np.floating) and not math.isfinite(float(value)):
        return None
    if isinstance(value, np.generic):
        return value.item()
    return value


def jsonable(value: Any) -> Any:
    """``value`` with numpy values converted and NaN/±inf replaced by None (valid JSON).

    Parameters
    ----------
    value : object
        A scalar, or dicts, lists, tuples and numpy arrays of them, nested.

    Returns
    -------
    object
        The same structure of Python values: dict keys as str, tuples and
        arrays as lists, numpy scalars as Python scalars, non-finite floats
        as None; any other value unchanged.
    """
    if value is None:
        return None
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [jsonable(v) for v in value.tolist()]
    return _scalar(value)


def finite_or_none(value: Any) -> float | None:
    """``value`` as a float, or None when it is None, NaN, ±inf or not a number."""
    if value is None:
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def finite_list(values: Any, digits: int | None = None) -> list[float | None]:
    """An array as a list of floats (rounded to ``digits`` decimals if given), None where not finite."""
    arr = np.asarray(values, dtype=np.float64)
    if digits is not None:
        arr = np.round(arr, digits)
    out = arr.astype(object)
    out[~np.isfinite(arr)] = None
    return out.tolist()


def iso_time(t: dt.datetime | None) -> str | None:
    """ISO 8601 with the UTC offset (a naive time is UTC); None for None."""
    if t is None:
        return None
    return (t if t.tzinfo else t.replace(tzinfo=dt.UTC)).isoformat()
