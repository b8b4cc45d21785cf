"""Reference data import: CSV and Parquet, queries, and all-or-nothing validation errors."""

from __future__ import annotations

import io

import pandas as pd

SUB_CSV = (
    "line_id,track,km,subsidence_mm,date\n"
    "4010,1,12.0001,-1.2,2016-05-01\n"
    "4010,1,12.0004,-1.3,2016-05-01\n"
    "4010,1,12.0007,-1.1,2016-05-01\n"
)
MAINT_CSV = (
    "line,track,km_from,km_to,type,date\n"
    "4010,1,12.0,12.5,Tamping,2012-03-04\n"
    "4010,1,12.2,12.3,rail replacement,2015-01-02\n"
    "4010,2,12.2,12.3,grinding,2019-01-02\n"
)
SUP_CSV = (
    "line_id,track,km_from,km_to,type,details\n"
    "4010,1,11.0,12.1,slab,L77-B\n"
    "4010,1,12.1,13.0,b91_pads,Sylomer SLS 1308G\n"
)


def _post(client, kind, text, name="f.csv", headers=None, **params):
    return client.post(f"/api/v1/reference/{kind}", params=params, headers=headers,
                       files={"file": (name, io.BytesIO(text if isinstance(text, bytes) else text.encode()))})


def _count(client, kind, **params):
    r = client.get(f"/api/v1/reference/{kind}", params=params)
    assert r.status_code == 200, r.text
    return len(r.json()["items"])


def test_import_and_query(client):
    for kind, text, n in (("subsidence", SUB_CSV, 3), ("maintenance", MAINT_CSV, 3),
                          ("superstructure", SUP_CSV, 2)):
        r = _post(client, kind, text)
        assert r.status_code == 201, r.text
        assert r.json() == {"kind": kind, "imported": n, "replaced": 0}
    items = client.get("/api/v1/reference/maintenance",
                       params={"line_id": "4010", "track": "1", "km_from": 12.25, "km_to": 13}).json()["items"]
    assert [(i["type"], i["date"]) for i in items] == [("tamping", "2012-03-04"), ("rail_replacement", "2015-01-02")]
    assert set(items[0]) == {"id", "line_id", "track", "km_from", "km_to", "type", "date"}
    assert _count(client, "maintenance", line_id="4010", type="grinding") == 1
    assert _count(client, "maintenance", line_id="4010", since="2014-01-01") == 2
    sup = client.get("/api/v1/reference/superstructure", params={"line_id": "4010", "km_from": 12.5}).json()["items"]
    assert [(s["type"], s["details"]) for s in sup] == [("b91_pads", "Sylomer SLS 1308G")]
    sub = client.get("/api/v1/reference/subsidence", params={"line_id": "4010", "km_to": 12.0005}).json()["items"]
    assert [s["subsidence_mm"] for s in sub] == [-1.2, -1.3] and sub[0]["date"] == "2016-05-01"
    # replace: the line/track's rows go, the new ones come, in one transaction
    r = _post(client, "superstructure", SUP_CSV.splitlines()[0] + "\n4010,1,11.0,13.0,timber,\n", mode="replace")
    assert r.json() == {"kind": "superstructure", "imported": 1, "replaced": 2}
    assert _count(client, "superstructure", line_id="4010") == 1


def test_parquet_import(client, tmp_path):
    df = pd.DataFrame({"line_id": ["A", "A"], "track": ["1", "1"], "km": [1.0, 1.5],
                       "subsidence_mm": [-1.0, -2.0], "date": pd.to_datetime(["2020-01-01", "2020-01-02"]),
                       "rail": [1, 2]})
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    r = _post(client, "subsidence", buf.getvalue(), name="s.parquet")
    assert r.status_code == 201, r.text
    items = client.get("/api/v1/reference/subsidence", params={"line_id": "A"}).json()["items"]
    assert [(i["km"], i["rail"], i["date"]) for i in items] == [(1.0, 1, "2020-01-01"), (1.5, 2, "2020-01-02")]


BAD_FILES = [
    ("subsidence", SUB_CSV.replace("12.0004", "12.x"), "row 2, column km", "not a finite number"),
    ("subsidence", SUB_CSV.replace("-1.1", "nan"), "row 3, column subsidence_mm", "not a finite"),
        ("subsidence", SUB_CSV.replace("2016-05-01\n4010,1,12.0007", "2016-13-01\n4010,1,12.0007"),
         "row 2, column date", "ISO date"),
        ("subsidence", SUB_CSV.replace("subsidence_mm", "depth"), "column subsidence_mm", "missing"),
        ("subsidence", SUB_CSV.replace("4010,1,12.0007", ",1,12.0007"), "row 3, column line_id", "empty"),
        ("maintenance", MAINT_CSV.replace("rail replacement", "polishing"), "row 2, column type", "polishing"),
        ("maintenance", MAINT_CSV.replace("12.0,12.5", "12.6,12.5"), "row 1, column km_to", "below km_from"),
        ("superstructure", SUP_CSV.replace("12.1,13.0", "12.1,abc"), "row 2, column km_to", "'abc'"),
]


def test_bad_row_or_column_imports_nothing(client):
    for kind, good in (("subsidence", SUB_CSV), ("maintenance", MAINT_CSV), ("superstructure", SUP_CSV)):
        assert _post(client, kind, good).status_code == 201
    for kind, text, field, needle in BAD_FILES:
        before = _count(client, kind)
        r = _post(client, kind, text)
        assert r.status_code == 422, r.text
        body = r.json()
        assert body["field"] == field and needle in body["detail"], body
        assert _count(client, kind) == before


def test_unreadable_and_oversized_files(make_client):
    client = make_client(max_reference_bytes=200)
    r = _post(client, "subsidence", b"PAR1 not really parquet", name="x.parquet")
    assert r.status_code == 422 and r.json()["field"] == "file"
    r = _post(client, "subsidence", SUB_CSV * 3)
    assert r.status_code == 413
    r = _post(client, "subsidence", "line_id,track,km,subsidence_mm,date\n")
    assert r.status_code == 422 and "no data rows" in r.json()["detail"]
    assert client.post("/api/v1/reference/gauge", files={"file": ("a.csv", b"x")}).status_code == 422


def _sections(client, line_id):
    r = client.get("/api/v1/reference/superstructure", params={"line_id": line_id})
    assert r.status_code == 200, r.text
    return [(s["km_from"], s["type"]) for s in r.json()["items"]]


def test_replace_over_a_line_with_runs_asks_for_confirm(client, short_sim_run):
    """mode=replace over a line and track that has runs: 409 naming ``confirm``, the line and its runs,
    nothing changed (also not the file's other line); confirm=true replaces; append needs no confirm."""
    path, _truth = short_sim_run  # a run of line SIM track 1
    sim_sup = SUP_CSV.replace("4010,", "SIM,")
    assert _post(client, "superstructure", sim_sup).status_code == 201
    with open(path, "rb") as fh:
        r = client.post("/api/v1/runs", files={"file": (path.name, fh, "application/x-hdf5")})
    assert r.status_code == 201, r.text
    before = _sections(client, "SIM")
    new = "line_id,track,km_from,km_to,type,details\nSIM,1,11.0,13.0,timber,\nOTHER,1,1.0,2.0,slab,\n"
    r = _post(client, "superstructure", new, mode="replace")
    assert r.status_code == 409, r.text
    body = r.json()
    assert body["field"] == "confirm"
    assert "line SIM track 1 has 1 run(s)" in body["detail"] and "confirm=true" in body["detail"], body
    assert _sections(client, "SIM") == before and _sections(client, "OTHER") == []
    # translated, the field unchanged
    r = _post(client, "superstructure", new, mode="replace", headers={"Accept-Language": "de"})
    assert r.status_code == 409 and r.json()["field"] == "confirm"
    assert "confirm=true" in r.json()["detail"] and "has 1 run(s)" not in r.json()["detail"], r.text
    # a track without runs: no question
    track_2 = "line_id,track,km_from,km_to,type,details\nSIM,2,11.0,13.0,timber,\n"
    assert _post(client, "superstructure", track_2, mode="replace").status_code == 201
    # append over the line with runs: no question either
    r = _post(client, "subsidence", SUB_CSV.replace("4010,", "SIM,"))
    assert r.status_code == 201, r.text
    r = _post(client, "superstructure", new, mode="replace", confirm="true")
    assert r.status_code == 201, r.text
    assert r.json() == {"kind": "superstructure", "imported": 2, "replaced": 2}
    assert _sections(client, "SIM") == [(11.0, "timber"), (11.0, "timber")]  # track 1's and track 2's
    assert _sections(client, "OTHER") == [(1.0, "slab")]
