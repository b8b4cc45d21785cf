"""The one CSV writer of the exports (issue 32 finding 4): formula starts defused, numbers kept."""

from __future__ import annotations

import csv
import io

import pytest

from app.core.csv_export import csv_lines, csv_text, escape_cell


@pytest.mark.parametrize("cell", ["=1+1", "+1+1", "-2+3", "@SUM(A1)", "\t=1", "\r=1", "-", "=", "-inf"])
def test_a_formula_start_is_written_as_text(cell):
    assert escape_cell(cell) == "'" + cell
    assert list(csv.reader(io.StringIO(csv_text(["a"], [[cell]]), newline=""))) == [["a"], ["'" + cell]]


@pytest.mark.parametrize("cell", [-1.5, 3, "-0.125", "+2", "1e-3", "-4.0E+2", "SIM", "a=b", "", None])
def test_numbers_and_plain_text_are_kept(cell):
    assert escape_cell(cell) == ("" if cell is None else cell)


def test_rows_are_written_whole_and_checked():
    text = csv_text(["a", "b"], [["x,y", 'say "hi"\nthen']])
    assert list(csv.DictReader(io.StringIO(text, newline=""))) == [{"a": "x,y", "b": 'say "hi"\nthen'}]
    with pytest.raises(ValueError, match="2 cells"):
        list(csv_lines(["a"], [["x", "y"]]))


def test_the_header_in_a_language_is_the_columns_labels_the_cells_unchanged():
    rows = [["SIM", 1.25, "=x"]]
    de = list(csv.reader(io.StringIO(csv_text(["line_id", "km_from", "asset_name"], rows, "de"), newline="")))
    assert de == [["Strecke", "km von [km]", "Anlagenname"], ["SIM", "1.25", "'=x"]]
    assert csv_text(["line_id", "km_from", "asset_name"], rows).startswith("line_id,km_from,asset_name\n")
    with pytest.raises(KeyError, match="no_such_column"):
        csv_text(["no_such_column"], [], "de")
