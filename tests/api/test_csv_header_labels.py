"""The CSV exports' header in the user's language (issue 34 item 1): ``header=labels`` writes each
column's label and unit in the request's language, the default (``fields``) the API's field names; the
cells are the same either way; any other ``header`` answers 422 naming it. Every column of every export
has a label translated into every language. On a real SQLite store holding a generated line."""

from __future__ import annotations

import csv
import datetime as dt
import io

import pytest

from app.condition.rail_findings import CSV_COLUMNS as FINDING_COLUMNS
from app.core.csv_labels import COLUMN_LABELS, column_label
from app.core.i18n import LANGUAGES
from app.places.sections import CSV_COLUMNS as SECTION_COLUMNS
from app.places.worklist import CSV_COLUMNS as PLACE_COLUMNS

LINE = "CSVL"
#: every CSV route written by the one writer, with its query and its columns
ROUTES = {
    "places": ("/api/v1/condition/places.csv", {"line_id": LINE, "include_closed": "true"}, PLACE_COLUMNS),
    "sections": ("/api/v1/condition/sections.csv", {"line_id": LINE}, SECTION_COLUMNS),
    "rail-findings": ("/api/v1/condition/rail-findings.csv", {"line_id": LINE}, FINDING_COLUMNS),
}


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    from fastapi.testclient import TestClient

    from app.condition.fleet import ingest_fleet
    from app.db.session import Database
    from app.main import create_app
    from app.simulate.fleet import FleetPlan, FleetSimulator, PlantedStep
    from app.simulate.track import generate_line
    from tests.api.support import auth_headers, create_api_key, make_settings, migrate_database

    tmp = tmp_path_factory.mktemp("csv-labels")
    settings = make_settings(tmp)
    migrate_database(settings.database_url)
    sim = FleetSimulator(generate_line(0.0, 2_000.0, seed=5),
                         FleetPlan(steps=(PlantedStep(1_000.0, 1_200.0, day=0.0, factor=1.6),)))
    db = Database(settings.database_url)
    ingest_fleet(db, sim, 5, line_id=LINE, start=dt.datetime(2024, 1, 8, 8, 0, tzinfo=dt.UTC), every_days=30.0,
                 seed=6)
    db.dispose()
    key = create_api_key(settings.database_url, "viewer")
    with TestClient(create_app(settings), headers=auth_headers(key)) as c:
        yield c


def _rows(text: str) -> list[list[str]]:
    return list(csv.reader(io.StringIO(text, newline="")))


@pytest.mark.parametrize("name", sorted(ROUTES))
def test_labels_in_the_users_language_field_names_by_default(client, name):
    path, params, columns = ROUTES[name]
    plain = client.get(path, params=params, headers={"Accept-Language": "de"})
    assert plain.status_code == 200, plain.text
    fields = client.get(path, params={**params, "header": "fields"}, headers={"Accept-Language": "de"})
    labels = client.get(path, params={**params, "header": "labels"}, headers={"Accept-Language": "de-CH,de;q=0.9"})
    assert fields.status_code == labels.status_code == 200, labels.text
    assert labels.headers["content-type"].startswith("text/csv")
    plain_rows, label_rows = _rows(plain.text), _rows(labels.text)
    assert plain_rows[0] == list(columns) and fields.text == plain.text
    # German words with their units, in the columns' order; the cells unchanged
    assert label_rows[0] == [column_label(c, "de") for c in columns]
    assert label_rows[1:] == plain_rows[1:]
    assert "Strecke" in label_rows[0] and label_rows[0] != plain_rows[0]
    french = _rows(client.get(path, params={**params, "header": "labels"}, headers={"Accept-Language": "fr"}).text)
    assert french[0] == [column_label(c, "fr") for c in columns] != label_rows[0]


def test_the_labels_name_words_and_units():
    assert column_label("km_from", "de") == "km von [km]"
    assert column_label("change", "de") == "Änderung [ln-Einheiten]"
    assert column_label("amplitude_percent_per_year", "de") == "Änderung der Amplitude [%/Jahr]"
    assert column_label("depth_mm", "fr") == "Profondeur du creux [mm]"
    assert column_label("days_to_next_tier", "it") == "Tempo al livello successivo [giorni]"
    assert column_label("line_id", "en") == "line" and column_label("speed_kmh", "en") == "speed [km/h]"


@pytest.mark.parametrize("name", sorted(ROUTES))
def test_a_bad_header_is_refused_naming_it(client, name):
    path, params, _columns = ROUTES[name]
    r = client.get(path, params={**params, "header": "Labels"})
    assert r.status_code == 422 and "header" in r.text and "fields, labels" in r.text, r.text


def test_every_column_of_every_export_has_a_label_in_every_language():
    from babel.messages.pofile import read_po

    from app.analytics.stiffness_index import INDEX_COLUMNS
    from app.core.csv_labels import SEGMENT_STATISTICS
    from app.core.i18n import catalogue_path
    from app.db.models import PROFILE_VALUE_COLUMNS
    from app.profiles.query import AGGREGATED_COLUMNS

    profile = ["wheel", "bin", "km", *PROFILE_VALUE_COLUMNS, *INDEX_COLUMNS]
    segments = ["wheel", "km_from", "km_to", "n_bins",
                *(f"{c}_{s}" for c in (*AGGREGATED_COLUMNS, *INDEX_COLUMNS) for s in SEGMENT_STATISTICS)]
    columns = dict.fromkeys([*PLACE_COLUMNS, *SECTION_COLUMNS, *FINDING_COLUMNS, *profile, *segments])
    unlabelled = []
    for c in columns:
        try:
            column_label(c, "en")
        except KeyError:
            unlabelled.append(c)
    assert not unlabelled, f"CSV columns without a label in app/core/csv_labels.py: {unlabelled}"
    words = {getattr(w, "msgid", w) for label, unit in COLUMN_LABELS.values() for w in (label, unit) if w}
    words |= set(SEGMENT_STATISTICS.values())
    for lang in LANGUAGES:
        if lang == "en":
            continue
        with catalogue_path(lang).open("rb") as fh:
            cat = read_po(fh, locale=lang)
        untranslated = sorted(w for w in words - {"km", "m", "mm", "%", "km/h", "m/s", "m/s²", "kN"}
                              if cat.get(w) is None or not cat.get(w).string or cat.get(w).fuzzy)
        assert not untranslated, (lang, untranslated)
        assert {column_label(c, lang) for c in columns} != {column_label(c, "en") for c in columns}
