"""docs/places.md gives the reasons of the places' settings beside their defaults: the defaults it
states are those of the settings group (app/places/settings.py), whose defaults are the numerics'."""

from __future__ import annotations

import json
import re
from pathlib import Path

from app.places.settings import PlacesSettings

DOC = Path(__file__).resolve().parents[2] / "docs" / "places.md"
_ROW = re.compile(r"^\| (?P<names>`TRACKVKF_\w+`(?:, `TRACKVKF_\w+`)*) \| (?P<default>[^|]+) \|", re.M)


def _values(cell: str, n: int) -> list:
    cell = cell.strip()
    if cell == "empty":
        return [""]
    if cell.startswith("`"):
        text = cell.split("`")[1]
        try:
            return [json.loads(text)]
        except ValueError:
            return [text]
    return [float(v) for v in cell.split(", ")][:n]


def _rows(text: str) -> dict[str, object]:
    out: dict[str, object] = {}
    for m in _ROW.finditer(text):
        names = [n.strip("`") for n in m.group("names").split(", ")]
        values = _values(m.group("default"), len(names))
        assert len(values) == len(names), m.group(0)
        out.update(zip(names, values, strict=True))
    return out


def _same(doc, default) -> bool:
    if isinstance(default, (int, float)) and not isinstance(default, bool):
        return float(doc) == float(default)
    if isinstance(default, (list, tuple)):
        return [float(v) for v in doc] == [float(v) for v in default]
    if isinstance(default, dict):
        return {k: [float(v) for v in lim] for k, lim in doc.items()} == \
            {k: [float(v) for v in lim] for k, lim in default.items()}
    return doc == default


def test_the_places_settings_table_states_the_groups_defaults():
    rows = _rows(DOC.read_text(encoding="utf-8"))
    assert len(rows) >= 20
    defaults = PlacesSettings.model_construct()  # the defaults, no environment
    wrong = {name: (doc, getattr(defaults, name.removeprefix("TRACKVKF_").lower()))
             for name, doc in rows.items()
             if not _same(doc, getattr(defaults, name.removeprefix("TRACKVKF_").lower()))}
    assert wrong == {}, "docs/places.md states other defaults than app/places/settings.py"
    assert set(rows) <= set(PlacesSettings.env_names())


def test_the_row_reader_sees_a_changed_default():
    rows = _rows("| `TRACKVKF_PLACES_GAP_M` | 12 | one segment |\n")
    assert not _same(rows["TRACKVKF_PLACES_GAP_M"], PlacesSettings.model_construct().places_gap_m)
