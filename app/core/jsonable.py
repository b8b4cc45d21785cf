"""Values made valid JSON: numpy scalars and arrays to Python, NaN and ±inf to None.

Used wherever results leave numpy for JSON: the job's metadata and wheel rows
in SQL (:mod:`app.db.results_writer`, :mod:`app.db.queue`), chunk records of
the fan-out worker and the files the CLI writes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["jsonable"]


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
