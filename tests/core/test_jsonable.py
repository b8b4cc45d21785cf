"""jsonable (app/core/jsonable.py): numpy values to Python, non-finite floats to None,
the result valid strict JSON."""

from __future__ import annotations

import json

import numpy as np

from app.core.jsonable import jsonable


def test_nested_numpy_values_become_strict_json():
    value = {
        1: np.float32(0.5),
        "orders": (np.int64(3), np.nan, float("inf")),
        "profile": np.array([[1.0, np.nan], [-np.inf, 2.0]]),
        "flag": np.bool_(True),
        "name": np.str_("11"),
        "none": None,
        "empty": [],
    }
    out = jsonable(value)
    assert out == {
        "1": 0.5,
        "orders": [3, None, None],
        "profile": [[1.0, None], [None, 2.0]],
        "flag": True,
        "name": "11",
        "none": None,
        "empty": [],
    }
    assert type(out["orders"][0]) is int and type(out["flag"]) is bool
    assert json.loads(json.dumps(out, allow_nan=False)) == out


def test_scalars():
    assert jsonable(np.float64("nan")) is None
    assert jsonable(np.float64(0.92)) == 0.92 and type(jsonable(np.float64(0.92))) is float
    assert jsonable(7) == 7 and jsonable("x") == "x" and jsonable(None) is None
