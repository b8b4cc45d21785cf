"""JSON documents from outside (metadata, GeoJSON, channel maps): parsed with bounded work.

Python's :func:`json.loads` recurses once per nesting level (a document
nested 100 000 deep raises :class:`RecursionError`) and refuses integers of
more than 4300 digits with a :class:`ValueError`; both used to surface as
500s. :func:`load_json` counts the nesting before parsing (linear time, no
recursion), reads integers of more than 300 digits as floats (``inf`` beyond
the float range, refused by the callers' finiteness checks) and answers
every problem as a :class:`RunFileError` naming the document.
"""

from __future__ import annotations

import json
import re
from typing import Any

import numpy as np

from app.core.i18n import _
from app.io.errors import RunFileError

__all__ = ["load_json", "json_depth", "MAX_INT_DIGITS"]

#: JSON integers with more digits than this are read as floats.
MAX_INT_DIGITS = 300
# a JSON string literal (with escapes); stripped before the brackets are counted
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)


def json_depth(text: str) -> int:
    """Deepest nesting of ``[``/``{`` in a JSON text, without parsing it (linear time)."""
    skeleton = _JSON_STRING.sub("", text).encode("ascii", "ignore")
    codes = np.frombuffer(skeleton, dtype=np.uint8)
    steps = np.zeros(codes.shape, dtype=np.int32)
    steps[(codes == ord("[")) | (codes == ord("{"))] = 1
    steps[(codes == ord("]")) | (codes == ord("}"))] = -1
    return int(np.cumsum(steps).max(initial=0))


def _parse_int(digits: str) -> int | float:
    return int(digits) if len(digits.lstrip("-")) <= MAX_INT_DIGITS else float(digits)


def load_json(text: str | bytes, *, field: str, max_depth: int) -> Any:
    """Parse a JSON document nested at most ``max_depth`` levels.

    Parameters
    ----------
    text : str or bytes
        The JSON text (bytes are decoded as UTF-8).
    field : str
        Name reported for problems of the document.
    max_depth : int
        Deepest nesting of objects and arrays accepted (the top level is 1).

    Returns
    -------
    Any
        The value. ``NaN``/``Infinity`` literals and numbers beyond the float
        range come back as floats (callers refuse non-finite numbers naming
        their field).

    Raises
    ------
    RunFileError
        ``field`` for text that is not UTF-8, not JSON or nested too deeply.
    """
    if isinstance(text, bytes | bytearray):
        try:
            text = bytes(text).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise RunFileError(field, _("not UTF-8 text (byte {byte})", byte=exc.start)) from None
    depth = json_depth(text)
    if depth > max_depth:
        raise RunFileError(field, _("nested deeper than {n} levels ({depth})", n=max_depth, depth=depth))
    try:
        return json.loads(text, parse_int=_parse_int, parse_constant=float)
    except json.JSONDecodeError as exc:
        raise RunFileError(field, _("not valid JSON: {error} at position {position}", error=exc.msg, position=exc.pos)) from None
    except (ValueError, RecursionError) as exc:  # belt and braces: the depth is checked above
        raise RunFileError(field, _("not valid JSON: {error}", error=str(exc)[:120])) from None
