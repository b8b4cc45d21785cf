"""The one CSV writer of every export: text cells that a spreadsheet would run are defused.

A spreadsheet opening a CSV runs a cell beginning with ``=``, ``+``, ``-`` or ``@`` as a formula, and
a leading tab or carriage return hides such a start from a naive check (CSV/formula injection). A text
cell beginning with one of these characters is written with a leading apostrophe (``'=HYPERLINK(...)``):
spreadsheets show it as text, and a reader of the CSV sees the original after the apostrophe. Numbers
(``int``/``float`` and strings that are a plain decimal number such as ``-0.125`` or ``1e-3``) are
written as they are, so a negative value stays a number.

Every export builds its rows and writes them through :func:`csv_text` or :func:`csv_lines`; a
columnar export (pyarrow) passes its text columns through :func:`escape_cell` first. The header is
the API's field names, or, given a language (an export asked with ``header=labels``), each column's
label and unit in that language (:mod:`app.core.csv_labels`).
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

from app.core.csv_labels import header_labels

__all__ = ["FORMULA_STARTS", "escape_cell", "csv_text", "csv_lines"]

#: First characters that make a spreadsheet treat a cell as a formula (or hide such a start).
FORMULA_STARTS: tuple[str, ...] = ("=", "+", "-", "@", "\t", "\r")
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


def escape_cell(value: Any) -> Any:
    """The cell as written: ``None`` as empty, a text beginning with one of :data:`FORMULA_STARTS`
    prefixed with ``'`` unless it is a plain decimal number, anything else unchanged.

    Parameters
    ----------
    value : Any
        One cell (text, number, ``None``).

    Returns
    -------
    Any
        The cell to hand to :func:`csv.writer` (text or number).
    """
    if value is None:
        return ""
    if isinstance(value, str) and value.startswith(FORMULA_STARTS) and not _NUMBER.fullmatch(value):
        return "'" + value
    return value


def csv_lines(header: Sequence[str], rows: Iterable[Sequence[Any]], lang: str | None = None) -> Iterator[str]:
    """The CSV text line by line (``\\n`` line ends): the header, then every row, each cell through
    :func:`escape_cell` (also the header's).

    Parameters
    ----------
    header : Sequence[str]
        Column names (the API's field names).
    rows : Iterable[Sequence[Any]]
        Rows of the same length as ``header``.
    lang : str, optional
        Write the header as the columns' labels with their units in this language
        (:func:`app.core.csv_labels.header_labels`); default: the column names.

    Yields
    ------
    str
        One written line each (a cell holding a line break stays quoted within its line).
    """
    buffer = io.StringIO()
    # "\r\n" as the writer's line end makes it quote every cell holding a CR or a LF (with "\n" alone
    # a lone CR went out unquoted and split the row); each line is then ended by "\n"
    writer = csv.writer(buffer, lineterminator="\r\n")
    first = header if lang is None else header_labels(header, lang)
    for block in ([first], rows):
        for cells in block:
            if len(cells) != len(header):
                raise ValueError(f"a CSV row has {len(cells)} cells, the header {len(header)}")
            writer.writerow([escape_cell(c) for c in cells])
            yield buffer.getvalue()[:-2] + "\n"
            buffer.seek(0)
            buffer.truncate()


def csv_text(header: Sequence[str], rows: Iterable[Sequence[Any]], lang: str | None = None) -> str:
    """The whole CSV as one text (see :func:`csv_lines`)."""
    return "".join(csv_lines(header, rows, lang))
