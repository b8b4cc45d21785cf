"""GET /condition/sections on a real SQLite store holding a generated year of runs: per 200 m section a
class from the speed-conditioned index of the 10 m rows, a lasting stiff section and a new one classed
E, healthy track A–C, the length per class now and a year before, the bad-input answers, and the
railway's own class scheme (TRACKVKF_PLACES_CLASS_SCHEME) in the answer and the CSV."""

from __future__ import annotations

import datetime as dt

import pytest

LINE = "SEC"


@pytest.fixture(scope="module")
def sections_client(tmp_path_factory):
    from fastapi.testclient import TestClient

    from app.condition.fleet import ingest_fleet
    from app.db import migrate
    from app.db.session import Database
    from app.main import create_app
    from app.simulate.fleet import FleetPlan, FleetSimulator, PlantedStep
    from app.simulate.track import generate_line
    from tests.api.support import auth_headers, create_api_key, make_settings

    tmp = tmp_path_factory.mktemp("sections")
    settings = make_settings(tmp)
    migrate.upgrade(settings.database_url)
    plan = FleetPlan(steps=(PlantedStep(2_000.0, 2_200.0, day=0.0, factor=1.6),
                            PlantedStep(3_000.0, 3_200.0, day=200.0, factor=1.6)))
    sim = FleetSimulator(generate_line(0.0, 4_000.0, seed=5), plan)
    db = Database(settings.database_url)
    ingest_fleet(db, sim, 14, line_id=LINE, start=dt.datetime(2024, 1, 8, 8, 0, tzinfo=dt.UTC), every_days=30.0,
                 seed=6)
    db.dispose()
    key = create_api_key(settings.database_url, "viewer")
    with TestClient(create_app(settings), headers=auth_headers(key)) as client:
        client.settings = settings
        client.key = key
        yield client


def _cls(body: dict, km: float) -> str:
    return next(s["class"] for s in body["sections"] if s["km_from"] <= km < s["km_to"])


def test_sections_class_the_line_now_and_a_year_ago(sections_client):
    r = sections_client.get("/api/v1/condition/sections", params={"line_id": LINE})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["section_m"] == 200 and body["limits"] == [0.05, 0.10, 0.17, 0.25]
    assert "ln(A/A_ref(class, v))" in body["quantity"]
    secs = body["sections"]
    assert len(secs) >= 19 and all(s["class"] in ("A", "B", "C", "D", "E", "") for s in secs)
    assert _cls(body, 2.1) == "E" and _cls(body, 3.1) == "E"
    healthy = [s["class"] for s in secs if s["class"] and not (1.8 <= s["km_from"] < 2.4 or 2.8 <= s["km_from"] < 3.4)]
    assert healthy and sum(c in "ABC" for c in healthy) / len(healthy) >= 0.8, healthy
    e = [s for s in secs if s["class"] == "E"]
    assert all(s["rms"] >= 0.25 for s in e)
    total = sum(s["km_to"] - s["km_from"] for s in secs) * 1000
    assert sum(body["length_by_class"].values()) == pytest.approx(total)
    # a year before the newest run: the lasting section was E already, the new one was not
    old = body["length_by_class_year_ago"]
    assert old is not None and body["run_id_year_ago"] is not None
    assert body["length_by_class"]["E"] >= old["E"] + 200.0 - 1e-6
    r100 = sections_client.get("/api/v1/condition/sections", params={"line_id": LINE, "section_m": 100}).json()
    assert len(r100["sections"]) >= 2 * len(secs) - 2


def test_sections_bad_input(sections_client):
    r = sections_client.get("/api/v1/condition/sections", params={"line_id": "NOPE"})
    assert r.status_code == 404 and r.json()["field"] == "line_id"
    r = sections_client.get("/api/v1/condition/sections", params={"line_id": LINE, "section_m": 205})
    assert r.status_code == 422 and r.json()["field"] == "section_m"
    r = sections_client.get("/api/v1/condition/sections", params={"line_id": LINE, "section_m": 0})
    assert r.status_code == 422 and r.json()["field"] == "section_m"


#: a railway's three classes: A and B are "1", C is "2", D and E are "3"
SCHEME = {"name": {"en": "Condition class", "de": "Zustandsklasse"},
          "classes": [{"code": "1", "of": ["A", "B"], "name": {"en": "good", "de": "gut"}},
                      {"code": "2", "of": ["C"], "name": {"en": "watch", "de": "beobachten"}},
                      {"code": "3", "of": ["D", "E"], "name": {"en": "plan work", "de": "Arbeit planen"}, "colour": "#c00"}]}


def test_sections_in_the_railways_class_scheme(sections_client):
    from fastapi.testclient import TestClient

    from app.main import create_app
    from tests.api.support import auth_headers

    default = sections_client.get("/api/v1/condition/sections", params={"line_id": LINE}).json()
    assert [k["code"] for k in default["scheme"]["classes"]] == ["A", "B", "C", "D", "E"]
    assert all(s["scheme_class"] == s["class"] for s in default["sections"])
    settings = sections_client.settings.model_copy(update={"places_class_scheme": SCHEME})
    with TestClient(create_app(settings), headers=auth_headers(sections_client.key)) as client:
        body = client.get("/api/v1/condition/sections", params={"line_id": LINE}).json()
        csv_text = client.get("/api/v1/condition/sections.csv", params={"line_id": LINE}).text
    assert body["scheme"]["name"] == "Condition class"
    assert [(k["code"], k["of"]) for k in body["scheme"]["classes"]] == [("1", ["A", "B"]), ("2", ["C"]), ("3", ["D", "E"])]
    assert body["scheme"]["classes"][2]["colour"] == "#c00"
    code = {"A": "1", "B": "1", "C": "2", "D": "3", "E": "3", "": ""}
    assert [s["scheme_class"] for s in body["sections"]] == [code[s["class"]] for s in body["sections"]]
    by_class = body["length_by_class"]
    assert body["length_by_scheme_class"]["3"] == pytest.approx(by_class["D"] + by_class["E"])
    assert body["length_by_scheme_class"]["1"] == pytest.approx(by_class["A"] + by_class["B"])
    old = body["length_by_class_year_ago"]
    assert body["length_by_scheme_class_year_ago"]["3"] == pytest.approx(old["D"] + old["E"])
    lines = csv_text.strip().split("\n")
    assert lines[0].split(",")[4:7] == ["class", "scheme_class", "scheme_class_name"]
    assert len(lines) == len(body["sections"]) + 1
    e_row = next(row.split(",") for row in lines[1:] if row.split(",")[4] == "E")
    assert e_row[5:7] == ["3", "plan work"]


def test_a_bad_class_scheme_stops_the_start_naming_it(sections_client):
    from app.main import create_app

    bad = {"classes": [{"code": "1", "of": ["A", "B", "C"]}, {"code": "2", "of": ["D"]}]}  # E nowhere
    with pytest.raises(ValueError, match="TRACKVKF_PLACES_CLASS_SCHEME: classes: every class"):
        create_app(sections_client.settings.model_copy(update={"places_class_scheme": bad}))
    with pytest.raises(ValueError, match=r"classes\[1\]\.of"):
        create_app(sections_client.settings.model_copy(update={"places_class_scheme": {
            "classes": [{"code": "1", "of": ["A", "B", "C", "D"]}, {"code": "2", "of": ["F"]}]}}))


def test_the_report_of_a_line_is_a_pdf_and_bad_input_is_named(sections_client):
    r = sections_client.get("/api/v1/condition/report.pdf", params={"line_id": LINE, "date": "2025-03-04"})
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/pdf" and r.content.startswith(b"%PDF-")
    assert f'filename="report-{LINE}-' in r.headers["content-disposition"] and "2025-03-04" in r.headers["content-disposition"]
    r = sections_client.get("/api/v1/condition/report.pdf", params={"line_id": "NOPE"})
    assert r.status_code == 404 and r.json()["field"] == "line_id"
    r = sections_client.get("/api/v1/condition/report.pdf", params={"line_id": LINE, "date": "2025-13-01"})
    assert r.status_code == 422 and "date" in r.text


def test_the_report_without_weasyprints_libraries_is_a_clear_503(sections_client, monkeypatch):
    """Pango missing (WeasyPrint's import fails, as it does without the library): the answer names
    the packages, not a traceback."""
    import sys

    monkeypatch.setitem(sys.modules, "weasyprint", None)  # import weasyprint → ImportError
    r = sections_client.get("/api/v1/condition/report.pdf", params={"line_id": LINE})
    assert r.status_code == 503, r.text
    assert r.json()["field"] == "report" and "libpango-1.0-0" in r.json()["detail"]


@pytest.mark.parametrize(("accept", "lang", "said"), [
    ("de-CH,de;q=0.9", "de", ("Zustandsbericht: Strecke SEC, Gleis 1", "Planungssitzung vom 04.03.2025",
                              "Abschnittsklassen", "ein Jahr zuvor (km)", "Arbeitsliste", "Wirkungen der Instandhaltung")),
    ("fr", "fr", ("Rapport d'état : ligne SEC, voie 1", "Réunion de planification du 4 mars 2025",
                  "Classes de sections", "un an avant (km)", "Liste de travail", "Effets de l'entretien")),
    ("it", "it", ("Rapporto sullo stato: linea SEC, binario 1", "Riunione di pianificazione del 4 mar 2025",
                  "Classi delle sezioni", "un anno prima (km)", "Lista di lavoro", "Effetti della manutenzione")),
])
def test_the_report_speaks_the_users_language(sections_client, accept, lang, said):
    """The report follows the browser's language (a user's own choice first): its text read back
    from the PDF (pdftotext) is the catalogue's, its dates and numbers (tables and plot ticks) the
    locale's, and no English of the report's messages or of the codes' words is left."""
    from tests.condition.report_text import english_leftovers, pdf_text

    r = sections_client.get("/api/v1/condition/report.pdf", params={"line_id": LINE, "date": "2025-03-04"},
                            headers={"Accept-Language": accept})
    assert r.status_code == 200, r.text
    text = pdf_text(r.content)
    for words in said:
        assert words in text, (words, text[:1500])
    assert english_leftovers(text, lang) == []
    # the same PDF in English holds what the check looks for: it can fail
    english = pdf_text(sections_client.get("/api/v1/condition/report.pdf", params={"line_id": LINE}).content)
    assert {"Condition report: line", "Section classes", "Work list", "Maintenance effects"} <= set(english_leftovers(english, lang))
    # numbers in the locale: the decimal comma of French and Italian (also the km ticks: 0,5),
    # Switzerland's point in German
    assert ("0,00" in text and "0,5 " in text) == (lang != "de") and ("0.00" in text) == (lang == "de"), text[:1500]
