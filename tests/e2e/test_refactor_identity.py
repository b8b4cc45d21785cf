"""The demo data set through the real pipeline: stored rows and API answers against a golden fingerprint.

The demo's four runs (two lines, three dates of line SIM), its reference data and line
geometries are uploaded and imported through the API (in-process app, SQLite), processed by
the local worker one job after the other (the order the change tests see their history in),
with one webhook registered so that the alerts outbox is written too (tests/demo_db.py: the
``processed_demo`` data set, processed once per session and shared with the dashboard tests;
this module reads a copy of it). Then every stored row
that the processing decides (profiles, wheels, jobs, the segment condition store, reference
curves, the outbox) and the answer of every GET the dashboard pages make (with their query
parameters) are fingerprinted (:mod:`tests.e2e.identity`) and compared with the committed
golden file ``tests/e2e/golden/refactor_identity.json``.

A change that moves code must leave every fingerprint as it was. A change that alters the
numbers ON PURPOSE regenerates the golden file, and its commit says which answers changed and
why::

    TRACKVKF_UPDATE_GOLDEN=1 .venv/bin/python -m pytest -q tests/e2e/test_refactor_identity.py

To see the values that differ: ``TRACKVKF_IDENTITY_DUMP=/tmp/before`` on the old commit,
``TRACKVKF_IDENTITY_DUMP=/tmp/after`` on the new one, then ``diff -r /tmp/before /tmp/after``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import inspect, text

from tests.api.support import auth_headers, create_api_key, make_settings
from tests.e2e.identity import Fingerprint, compare, csv_rows

GOLDEN = Path(__file__).with_name("golden") / "refactor_identity.json"
UPDATE_ENV = "TRACKVKF_UPDATE_GOLDEN"
#: tables whose rows the processing of the data set decides (the others hold users, keys, audit)
TABLES = (
    "runs", "jobs", "job_chunks", "profile_bins", "wheel_oor", "condition_lines", "condition_runs",
    "segment_condition", "condition_overview", "condition_flags", "reference_curves", "webhooks",
    "webhook_deliveries", "ref_subsidence", "ref_maintenance", "ref_superstructure", "line_geometries",
)


class Processed:
    """The processed data set: a test client on its database and the ids the pages use."""

    def __init__(self, client, db, run_ids: list[int], geometry_ids: list[int]) -> None:
        self.client, self.db, self.run_ids, self.geometry_ids = client, db, run_ids, geometry_ids

    def get(self, path: str, **params: Any):
        r = self.client.get(f"/api/v1{path}", params=params)
        assert r.status_code == 200, f"GET {path} {params}: {r.status_code} {r.text[:500]}"
        return r


@pytest.fixture(scope="module")
def processed(processed_demo, tmp_path_factory) -> Iterator[Processed]:
    """A test client on a copy of the processed demo (tests/demo_db.py: processed once per session)."""
    from fastapi.testclient import TestClient

    from app.db.session import Database
    from app.main import create_app

    tmp = tmp_path_factory.mktemp("identity")
    url, store = processed_demo.copy_to(tmp)
    settings = make_settings(tmp, database_url=url, run_store=store)
    key = create_api_key(settings.database_url, "admin", "identity-reader")
    db = Database(settings.database_url)
    with TestClient(create_app(settings), headers=auth_headers(key)) as client:
        yield Processed(client, db, list(processed_demo.run_ids), list(processed_demo.geometry_ids))
    db.dispose()


def _tables(p: Processed, fp: Fingerprint, tables: tuple[str, ...] = TABLES) -> None:
    """Every row of ``tables`` (default :data:`TABLES`), ordered by the primary key (columns from the
    schema itself)."""
    insp = inspect(p.db.engine)
    with p.db.engine.connect() as conn:
        for table in tables:
            keys = insp.get_pk_constraint(table)["constrained_columns"]
            rows = conn.execute(text(f"SELECT * FROM {table} ORDER BY {', '.join(keys)}")).mappings().all()
            values = []
            for row in rows:
                row = dict(row)
                for name, value in row.items():  # JSON columns come back as text on SQLite
                    if isinstance(value, str) and value[:1] in "[{":
                        try:
                            row[name] = json.loads(value)
                        except ValueError:
                            pass
                values.append(row)
            fp.add(f"table/{table}", values)


def _answers(p: Processed, fp: Fingerprint) -> None:
    """The answers of the GETs the dashboard pages make, with their query parameters."""
    sim, simb = p.run_ids[0], p.run_ids[3]
    line = {"line_id": "SIM", "track": "1"}
    json_gets: list[tuple[str, str, dict[str, Any]]] = [
        # runs page
        ("runs", "/runs", {"limit": 200}),
        ("runs-all", "/runs", {"limit": 500, "offset": 0}),
        ("jobs", "/jobs", {}),
        # wheels page
        ("wheels-trend-SIM-1", "/wheels/trend", {"vehicle_id": "SIM-1"}),
        ("wheels-trend-SIM-2", "/wheels/trend", {"vehicle_id": "SIM-2"}),
        # line view
        ("analytics-segments", "/analytics/segments", {**line, "wheel": "12", "segment_m": 100, "align": "true"}),
        ("analytics-segments-index", "/analytics/segments", {**line, "wheel": "12", "segment_m": 100,
                                                             "align": "true", "value": "index"}),
        ("analytics-segment-trend", "/analytics/segment-trend", {**line, "km": 12.5, "wheel": "12"}),
        ("analytics-segment-trend-index", "/analytics/segment-trend", {**line, "km": 12.5, "wheel": "12",
                                                                       "value": "index"}),
        # correlations page
        ("analytics-subsidence-fit", "/analytics/subsidence-fit", {**line, "max_points": 1500}),
        ("analytics-subsidence-fit-normalised", "/analytics/subsidence-fit", {**line, "normalise": "true"}),
        ("analytics-unsprung-mass", "/analytics/unsprung-mass", {**line, "max_points": 1500}),
        ("analytics-maintenance", "/analytics/maintenance", {**line}),
        ("analytics-superstructure", "/analytics/superstructure", {**line}),
        ("analytics-superstructure-power-law", "/analytics/superstructure", {**line, "conditioning": "power_law"}),
        ("analytics-speed-normalisation", "/analytics/speed-normalisation", {**line}),
        ("analytics-reference-curves", "/analytics/reference-curves", {**line}),
        ("analytics-reference-curves-SIM-B", "/analytics/reference-curves", {"line_id": "SIM-B"}),
        (f"run-{sim + 2}-alignment", f"/runs/{sim + 2}/alignment", {}),
        (f"run-{sim}-predicted-subsidence", f"/runs/{sim}/predicted-subsidence", {"wheel": "12"}),
        (f"run-{sim + 1}-speed-normalised-profile", f"/runs/{sim + 1}/speed-normalised-profile", {"wheel": "12"}),
        # reference data (stiffness map shading, lists)
        ("reference-superstructure", "/reference/superstructure", {**line, "km_from": 12.0, "km_to": 13.2}),
        ("reference-maintenance", "/reference/maintenance", {**line, "km_from": 12.0, "km_to": 13.2}),
        ("reference-subsidence", "/reference/subsidence", {**line}),
        # map page
        ("geometry", "/geometry", {}),
        # condition page
        ("condition-lines", "/condition/lines", {}),
        ("condition-heatmap", "/condition/heatmap", {**line}),
        ("condition-heatmap-10m-wheel", "/condition/heatmap", {**line, "segment_m": 10, "wheel": "11",
                                                               "km_from": 12.2, "km_to": 12.9}),
        ("condition-places", "/condition/places", {"include_closed": "true"}),
        ("condition-sections", "/condition/sections", {**line}),
        ("condition-trend", "/condition/trend", {**line, "km": 12.5, "segment_m": 10}),
        ("condition-trend-100m", "/condition/trend", {**line, "km": 12.55, "segment_m": 100}),
        ("condition-maintenance-effect", "/condition/maintenance-effect", {**line}),
        ("condition-changes", "/condition/changes", {**line}),
        ("condition-flags", "/condition/flags", {"since": 0}),
        ("webhooks", "/webhooks", {}),
        ("webhook-deliveries", "/webhooks/deliveries", {"limit": 20}),
    ]
    for run_id in p.run_ids:
        json_gets += [
            (f"run-{run_id}", f"/runs/{run_id}", {}),
            (f"run-{run_id}-jobs", f"/runs/{run_id}/jobs", {}),
            (f"run-{run_id}-wheels", f"/runs/{run_id}/wheels", {}),
            (f"run-{run_id}-condition-changes", f"/condition/runs/{run_id}/changes", {}),
            # stiffness map: the first request, then the displayed range of every wheel
            (f"run-{run_id}-profile-first", f"/runs/{run_id}/profile", {"wheel": "11", "max_points": 4}),
        ]
        for wheel in ("11", "12", "41", "42"):
            json_gets += [
                (f"run-{run_id}-profile-{wheel}-map", f"/runs/{run_id}/profile", {
                    "wheel": wheel, "km_from": 12.0, "km_to": 13.2, "max_points": 2000,
                    "columns": "sleeper_amp,speed_mean,sleeper_force_amp", "index": "true", "layout": "columns"}),
                (f"run-{run_id}-profile-{wheel}-rows", f"/runs/{run_id}/profile", {"wheel": wheel}),
            ]
        json_gets += [
            # line view: each run's 10 m profile of the chosen wheel
            (f"run-{run_id}-profile-12-10m", f"/runs/{run_id}/profile", {
                "wheel": "12", "level": 10, "max_points": 3000, "columns": "sleeper_amp", "layout": "columns"}),
            (f"run-{run_id}-profile-12-100m", f"/runs/{run_id}/profile", {"wheel": "12", "level": 100}),
        ]
    for gid in p.geometry_ids:
        json_gets += [
            (f"geometry-{gid}", f"/geometry/{gid}", {}),
            (f"geometry-{gid}-indicator", f"/geometry/{gid}/indicator", {"quantity": "sleeper_amp", "segment_m": 100}),
        ]
    effects = p.get("/condition/maintenance-effect", **line).json()["items"]
    for item in effects:
        if item["n_runs"]:
            json_gets.append((f"condition-maintenance-effect-{item['action_id']}",
                              f"/condition/maintenance-effect/{item['action_id']}", {}))
    json_gets.append((f"run-{sim}-spectrogram", f"/runs/{sim}/spectrogram",
                      {"wheel": "11", "km_from": 12.4, "km_to": 12.55}))
    json_gets.append((f"run-{simb}-condition-heatmap", "/condition/heatmap", {"line_id": "SIM-B"}))
    for name, path, params in json_gets:
        fp.add(f"api/{name}", p.get(path, **params).json())
    csv_gets = [
        (f"run-{sim}-profile-csv", f"/runs/{sim}/profile.csv", {}),
        (f"run-{sim}-profile-csv-10m-index", f"/runs/{sim}/profile.csv", {"wheel": "12", "level": 10, "index": "true"}),
        (f"run-{simb}-profile-csv-11", f"/runs/{simb}/profile.csv", {"wheel": "11"}),
        ("condition-places-csv", "/condition/places.csv", {**line, "include_closed": "true"}),
    ]
    for name, path, params in csv_gets:
        fp.add(f"api/{name}", csv_rows(p.get(path, **params).text))
    fp.add("api/condition-places-geojson", p.get("/condition/places.geojson", **line, include_closed="true").json())


def test_processed_demo_identical_to_golden(processed: Processed) -> None:
    """Stored rows and API answers of the processed demo data set equal the golden fingerprint."""
    fp = Fingerprint()
    _tables(processed, fp)
    _answers(processed, fp)
    if os.environ.get(UPDATE_ENV):
        GOLDEN.parent.mkdir(parents=True, exist_ok=True)
        GOLDEN.write_text(json.dumps(fp.to_json(), indent=1, sort_keys=True) + "\n")
        return
    assert GOLDEN.is_file(), f"no golden file {GOLDEN}: make it with {UPDATE_ENV}=1 (see the module docstring)"
    golden = json.loads(GOLDEN.read_text())
    assert golden.get("float_digits") == fp.to_json()["float_digits"], "float_digits of the golden file differ"
    diff = compare(golden, fp)
    assert not diff, (
        f"{len(diff)} of {len(fp.answers)} fingerprints differ from {GOLDEN.name}:\n  " + "\n  ".join(diff)
        + f"\nA change of numbers on purpose: {UPDATE_ENV}=1 .venv/bin/python -m pytest -q tests/e2e/test_refactor_identity.py"
        + "\nTo see the values: run with TRACKVKF_IDENTITY_DUMP=<dir> on both commits and diff -r the dirs."
    )


_SET_AMP = "UPDATE segment_condition SET amp_mean = :v WHERE run_id = :r AND seg_m = :m AND wheel = :w AND seg = :s"


def test_fingerprint_sees_a_changed_number(processed: Processed) -> None:
    """The fingerprint is not blind: one stored amplitude changed by 1e-6 changes its table's and part's hash."""
    fp = Fingerprint(dump=False)
    _tables(processed, fp, ("segment_condition",))
    before = fp.answers["table/segment_condition"]
    with processed.db.write() as session:
        row = session.execute(text("SELECT run_id, seg_m, wheel, seg, amp_mean FROM segment_condition "
                                   "ORDER BY run_id, seg_m, wheel, seg LIMIT 1")).one()
        key = {"r": row.run_id, "m": row.seg_m, "w": row.wheel, "s": row.seg}
        session.execute(text(_SET_AMP), {"v": row.amp_mean * (1 + 1e-6), **key})
    try:
        after = Fingerprint(dump=False)
        _tables(processed, after, ("segment_condition",))
        now = after.answers["table/segment_condition"]
        assert now["sha256"] != before["sha256"]
        changed = [k for k in before["parts"] if before["parts"][k] != now["parts"][k]]
        assert changed == ["amp_mean"]
        assert compare({"answers": {"table/segment_condition": before}},
                       Fingerprint({"table/segment_condition": now}, dump=False)) == [
            "table/segment_condition: differs (changed amp_mean)"]
    finally:
        with processed.db.write() as session:
            session.execute(text(_SET_AMP), {"v": row.amp_mean, **key})
