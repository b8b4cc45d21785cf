"""Assets (known discontinuities) over the API on a real migrated SQLite database: CSV and GeoJSON
import replacing per line and track, bad files refused whole with the row and column named, roles,
the audit, and the labels and muting of places on them (app.assets.labels)."""

from __future__ import annotations

import json

import pytest

CSV = ("line_id,track,type,km,km_to,name\n"
       "L1,1,switch,12.100,,W 12\n"
       "L1,1,Bridge,12.500,12.560,Aare bridge\n"
       "L1,,level crossing,13.020,,LC Feld\n"
       "L2,1,weld,3.000,,\n")


def _post(client, name: str, body: bytes | str, ctype: str = "text/csv"):
    return client.post("/api/v1/assets", files={"file": (name, body, ctype)})


def test_csv_import_lists_filters_and_replaces(make_client):
    client = make_client(parse_isolated=False)
    r = _post(client, "assets.csv", CSV)
    assert r.status_code == 201, r.text
    assert r.json() == {"imported": 4, "replaced": 0}
    items = client.get("/api/v1/assets", params={"line_id": "L1", "track": "1"}).json()
    assert items["total"] == 3  # the level crossing has no track: on every track of L1
    assert [(a["type"], a["km"], a["km_to"]) for a in items["items"]] == [
        ("switch", 12.1, None), ("bridge", 12.5, 12.56), ("level_crossing", 13.02, None)]
    assert items["items"][1]["name"] == "Aare bridge"
    assert client.get("/api/v1/assets", params={"type": "weld"}).json()["total"] == 1
    # a second import of L1 track 1 replaces those, leaves L1 (no track) and L2 alone
    r = _post(client, "again.csv", "line_id,track,type,km\nL1,1,insulated_joint,12.2\n")
    assert r.json() == {"imported": 1, "replaced": 2}
    assert client.get("/api/v1/assets").json()["total"] == 3
    audit = client.get("/api/v1/audit", params={"action": "assets.import"}).json()["items"]
    assert len(audit) == 2


def test_geojson_import_keeps_the_coordinates(make_client):
    client = make_client(parse_isolated=False)
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [7.44, 46.95]},
         "properties": {"line_id": "G", "track": "2", "type": "switch", "km": 1.25, "name": "W1"}},
        {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[7.45, 46.95], [7.451, 46.951], [7.452, 46.952]]},
         "properties": {"line_id": "G", "track": "2", "type": "bridge", "km": 1.5, "km_to": 1.6}},
        {"type": "Feature", "geometry": None, "properties": {"line_id": "G", "track": "2", "type": "weld", "km": 1.7}},
    ]}
    r = _post(client, "assets.geojson", json.dumps(doc), "application/geo+json")
    assert r.status_code == 201, r.text
    items = client.get("/api/v1/assets", params={"line_id": "G"}).json()["items"]
    assert [(a["lon"], a["lat"]) for a in items] == [(7.44, 46.95), (7.451, 46.951), (None, None)]


@pytest.mark.parametrize(("body", "field"), [
    ("line_id,track,type,km\nL1,1,switch,12.1\nL1,1,tunnel,12.2\n", "row 2, column type"),
    ("line_id,track,type,km\nL1,1,switch,abc\n", "row 1, column km"),
    ("line_id,track,type,km\nL1,1,switch,nan\n", "row 1, column km"),
    ("line_id,track,type,km,km_to\nL1,1,bridge,12.5,12.4\n", "row 1, column km_to"),
    ("line_id,track,type,km\n,1,switch,12.1\n", "row 1, column line_id"),
    ("line_id,track,km\nL1,1,12.1\n", "column type"),
    ("line_id,track,type,km\n", "file"),
    ("", "file"),
    ('{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [700, 46]},'
     ' "properties": {"line_id": "G", "track": "1", "type": "switch", "km": 1}}]}', "feature 1, geometry"),
    ('{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": null,'
     ' "properties": {"line_id": "G", "track": "1", "type": "switch"}}]}', "feature 1, property km"),
    ('{"type": "Feature"}', "file"),
    # issue 32 finding 8: a 400-digit number overflowed float() uncaught (500 without parse isolation)
    ('{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": null,'
     ' "properties": {"line_id": "G", "track": "1", "type": "switch", "km": 1' + "0" * 400 + '}}]}',
     "feature 1, property km"),
    ('{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [1'
     + "0" * 400 + ', 46]}, "properties": {"line_id": "G", "track": "1", "type": "switch", "km": 1}}]}',
     "feature 1, geometry"),
])
def test_a_bad_file_is_refused_whole_naming_the_row_and_column(make_client, body, field):
    client = make_client(parse_isolated=False)
    assert _post(client, "ok.csv", CSV).status_code == 201
    r = _post(client, "bad.json" if body.startswith("{") else "bad.csv", body)
    assert r.status_code == 422, r.text
    assert r.json()["field"] == field, r.json()
    assert client.get("/api/v1/assets").json()["total"] == 4  # nothing half-written, nothing replaced


def test_the_bounded_parser_and_the_size_limit(make_client):
    client = make_client(max_reference_bytes=2000)  # parse_isolated: the child process, as deployed
    r = _post(client, "assets.csv", CSV)
    assert r.status_code == 201, r.text
    r = _post(client, "bad.csv", "line_id,track,type,km\nL1,1,tunnel,1\n")
    assert r.status_code == 422 and r.json()["field"] == "row 1, column type"
    r = _post(client, "big.csv", "line_id,track,type,km\n" + "L9,1,weld,1.0\n" * 200)
    assert r.status_code == 413 and r.json()["field"] == "file"


def test_roles_viewer_reads_engineer_imports_admin_deletes(make_client):
    admin = make_client(parse_isolated=False)
    engineer = make_client(role="engineer", parse_isolated=False)
    viewer = make_client(role="viewer", parse_isolated=False)
    assert _post(viewer, "a.csv", CSV).status_code == 403
    assert _post(engineer, "a.csv", CSV).status_code == 201
    first = viewer.get("/api/v1/assets").json()["items"][0]["id"]
    assert engineer.delete(f"/api/v1/assets/{first}").status_code == 403
    assert admin.delete(f"/api/v1/assets/{first}").status_code == 204
    r = admin.delete(f"/api/v1/assets/{first}")
    assert r.status_code == 404 and r.json()["field"] == "asset_id"
    assert viewer.get("/api/v1/assets").json()["total"] == 3
    assert admin.get("/api/v1/assets", params={"type": "tunnel"}).status_code == 422


def test_places_are_labelled_with_their_assets_and_muted_types_stay_listed(make_client):
    from app.assets.labels import label_places
    from app.db.session import Database

    client = make_client(parse_isolated=False, places_muted_asset_types="switch,level_crossing")
    assert _post(client, "a.csv", CSV).status_code == 201
    db = Database(client.settings.database_url)
    try:
        with db.read() as s:
            # km: at the switch (within 20 m), next to the bridge, on nothing, at the level crossing (no track)
            out = label_places(s, client.settings, "L1", "1", [12.085, 12.570, 12.800, 13.000],
                               [12.095, 12.590, 12.830, 13.010])
            assert label_places(s, client.settings, "L1", "1", [], []) == []
            other = label_places(s, client.settings, "L2", "2", [2.99], [3.01])
    finally:
        db.dispose()
    assert [[a["type"] for a in p.assets] for p in out] == [["switch"], ["bridge"], [], ["level_crossing"]]
    assert [p.muted for p in out] == [True, False, False, True]
    assert "switch" in out[0].muted_reason and "TRACKVKF_PLACES_MUTED_ASSET_TYPES" in out[0].muted_reason
    assert out[1].muted_reason is None and out[0].assets[0]["name"] == "W 12"
    assert other[0].assets == []  # the weld is on track 1


def test_an_unknown_muted_type_is_an_error_naming_the_setting(tmp_path):
    from app.assets.labels import muted_types
    from tests.api.support import make_settings

    assert muted_types(make_settings(tmp_path, places_muted_asset_types=" weld, switch")) == ("weld", "switch")
    with pytest.raises(ValueError, match="TRACKVKF_PLACES_MUTED_ASSET_TYPES: 'tunnel'"):
        muted_types(make_settings(tmp_path, places_muted_asset_types="switch,tunnel"))


def test_a_place_on_many_assets_gets_a_capped_list_and_the_count_of_the_rest(make_client):
    """issue 32 finding 7: a place on a dense register was labelled with every asset (16 650 on one
    place); now at most MAX_LABELS_PER_PLACE, the rest counted, a muted type beyond the cap still mutes."""
    from app.assets.labels import MAX_LABELS_PER_PLACE, label_places
    from app.db.session import Database

    n = MAX_LABELS_PER_PLACE + 40
    rows = "".join(f"L9,1,weld,{5.0 + i * 0.001:.3f},,W{i}\n" for i in range(n))
    rows += f"L9,1,switch,{5.0 + n * 0.001:.3f},,S1\n"  # after the welds: beyond the cap
    client = make_client(parse_isolated=False, places_muted_asset_types="switch")
    assert _post(client, "dense.csv", "line_id,track,type,km,km_to,name\n" + rows).status_code == 201
    db = Database(client.settings.database_url)
    try:
        with db.read() as s:
            (p, far) = label_places(s, client.settings, "L9", "1", [5.0, 9.0], [5.0 + n * 0.001, 9.01])
    finally:
        db.dispose()
    assert len(p.assets) == MAX_LABELS_PER_PLACE and p.assets_more == n + 1 - MAX_LABELS_PER_PLACE
    assert [a["name"] for a in p.assets[:2]] == ["W0", "W1"] and p.muted and "switch" in p.muted_reason
    assert far.assets == [] and far.assets_more == 0 and not far.muted


@pytest.mark.parametrize(("lang", "detail"), [
    ("de-CH,de;q=0.9", "row 1, column type: 'tunnel' ist keiner von switch, crossing"),
    ("fr", "row 1, column type: 'tunnel' n'est pas l'un de switch, crossing"),
    ("it", "row 1, column type: 'tunnel' non è uno tra switch, crossing"),
    (None, "row 1, column type: 'tunnel' is not one of switch, crossing"),
])
def test_a_bad_file_is_answered_in_the_users_language(make_client, lang, detail):
    """The file's error in the request's language, the row and column named (the field stays the
    API's): read in the parse child process, as deployed, and sent back to the service."""
    client = make_client()
    headers = {"Accept-Language": lang} if lang else {}
    r = client.post("/api/v1/assets", files={"file": ("bad.csv", "line_id,track,type,km\nL1,1,tunnel,1\n", "text/csv")},
                    headers=headers)
    assert r.status_code == 422 and r.json()["field"] == "row 1, column type", r.text
    assert r.json()["detail"].startswith(detail), r.json()
    if lang and lang.startswith("de"):
        r = client.post("/api/v1/assets", headers=headers,
                        files={"file": ("bad.csv", "line_id,track,type,km,km_to\nL1,1,bridge,12.5,12.4\n", "text/csv")})
        assert r.json() == {"field": "row 1, column km_to", "detail": "row 1, column km_to: 12.4 liegt unter km 12.5"}
        r = client.post("/api/v1/assets", headers=headers, files={"file": ("bad.csv", "line_id,track,km\nL1,1,12.1\n",
                                                                           "text/csv")})
        assert r.json()["detail"].startswith("column type: fehlt (nötige Kopfzeile: line_id,track,type,km"), r.json()
