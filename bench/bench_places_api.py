"""The work list and a place's history for a 50 km line with a year of daily runs: answer times of
``GET /condition/places`` (first page, ranked), its CSV export (every listed place), ``GET
/condition/places/{id}`` (the place with the longest history) and a status change, through the API
(the app in process, an API key), on SQLite and PostgreSQL. Target: each ≤ 1 s (issue 25).

The places' tables are written directly (not through VKF and the publish step — a year of a 50 km line
through the pipeline would take days): 365 daily runs applied to line ``B50`` (km 0–50), ``--places``
places found over the year (first seen on a uniform day, each with an observation on every later run
until it goes inactive after a random life; tiers, outlooks, statuses, events, action links spread as
the service writes them), and a tamping every 5 km in the maintenance table.

Usage::

    .venv/bin/python bench/bench_places_api.py [--db sqlite|postgresql|both] [--places 1500] [--repeat 7]
    .venv/bin/python bench/bench_places_api.py --db none --update 60   # the publish step's added time
"""

from __future__ import annotations

import argparse
import datetime as dt
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sqlalchemy import insert  # noqa: E402

from app.analysis.units import DAYS_PER_YEAR  # noqa: E402
from app.db import migrate  # noqa: E402
from app.db.models import (  # noqa: E402
    ConditionLine,
    MaintenanceAction,
    Place,
    PlaceAction,
    PlaceEventRow,
    PlaceObservation,
    PlaceRun,
    PlaceStatusChange,
)
from app.db.session import Database  # noqa: E402

LINE, KM, DAYS = "B50", 50.0, 365
START = dt.datetime(2025, 1, 1, 6, 0, tzinfo=dt.UTC)
VERSION = "trackvkf-pipeline/3+bench0000000"


def _chunks(rows: list[dict], n: int = 20_000):
    for i in range(0, len(rows), n):
        yield rows[i:i + n]


def generate(db: Database, n_places: int, seed: int = 0) -> dict:
    """Write the line's year of places; counts of what was written."""
    rng = np.random.default_rng(seed)
    times = [START + dt.timedelta(days=d) for d in range(DAYS)]
    run_ids = list(range(1, DAYS + 1))
    places, obs, events, status, links = [], [], [], [], []
    with db.write() as s:
        line = ConditionLine(line_id=LINE, track="1", bin_length_m=0.25, km_min=0.0, km_max=KM)
        s.add(line)
        s.flush()
        s.execute(insert(PlaceRun), [{"run_id": r, "line_key": line.id, "run_time": t, "method_version": VERSION,
                                      "start_m": 0.0, "end_m": KM * 1000, "n_places": 0, "n_events": 0,
                                      "applied_at": t} for r, t in zip(run_ids, times, strict=True)])
        s.execute(insert(MaintenanceAction), [{"line_id": LINE, "track": "1", "km_from": k, "km_to": k + 0.3,
                                               "type": "tamping", "date": (START + dt.timedelta(days=30 * i)).date(),
                                               "imported_at": START}
                                              for i, k in enumerate(np.arange(2.0, KM, 5.0))])
        for pid in range(1, n_places + 1):
            first = int(rng.integers(0, DAYS - 2))
            active = rng.random() < 0.6
            life = DAYS - first if active else int(rng.integers(2, DAYS - first + 1))
            last = first + life - 1
            start = float(rng.integers(0, int(KM * 100) - 5)) * 10.0
            length = float(rng.integers(1, 6)) * 10.0
            direction = int(rng.choice([-1, 1]))
            tier = int(rng.choice([0, 1, 1, 1, 2, 2, 3]))
            level0 = direction * (0.15 + 0.1 * tier)
            rate = float(rng.normal(0.1, 0.1))
            listed = rng.random() < 0.8
            st = str(rng.choice(["open", "open", "open", "acknowledged", "planned", "fixed", "false_alarm"]))
            days_to = float(rng.uniform(10, 400)) if rng.random() < 0.4 and tier < 3 else None
            places.append({
                "id": pid, "line_key": line.id, "direction": direction, "start_m": start, "end_m": start + length,
                "peak_m": start + length / 2, "centre_m": start + length / 2, "cls": "b91_pads", "baseline": 0.0,
                "explained_by": None, "tier": tier, "listed": listed, "active": active, "misses": 0,
                "lower_runs": 0, "level": level0 + direction * rate * life / DAYS_PER_YEAR, "change": level0,
                "severity": abs(level0) / 0.3, "evidence": 3, "wheels": 15, "wheel_labels": "11,12,21,22",
                "runs_confirming": life, "tendency": "growing" if rate > 0.15 else "stable",
                "rate_per_year": rate, "rate_low": rate - 0.05, "rate_high": rate + 0.05,
                "next_limit": 0.45 if tier < 3 else None, "days_to_next": days_to,
                "first_run_id": run_ids[first], "last_run_id": run_ids[last], "first_seen": times[first],
                "last_confirmed": times[last], "method_version": VERSION, "status": st,
                "status_comment": None if st == "open" else "bench", "status_by": None if st == "open" else "eng",
                "status_at": None if st == "open" else times[last], "created_at": times[first],
                "updated_at": times[last]})
            noise = rng.normal(0, 0.02, life)
            for k in range(life):
                d = first + k
                obs.append({"place_id": pid, "run_id": run_ids[d], "run_time": times[d],
                            "day": (times[d] - dt.datetime(1970, 1, 1, tzinfo=dt.UTC)).total_seconds() / 86400,
                            "start_m": start, "end_m": start + length, "centre_m": start + length / 2,
                            "peak_m": start + length / 2, "level": level0 + direction * rate * k / DAYS_PER_YEAR + noise[k],
                            "change": level0, "tier": tier, "severity": abs(level0) / 0.3, "evidence": 3,
                            "wheels": 15, "wheel_labels": "11,12,21,22", "speed_kmh": float(rng.uniform(90, 110)),
                            "method_version": VERSION})
            events.append({"place_id": pid, "run_id": run_ids[min(first + 1, last)], "kind": "new", "old_tier": None,
                           "new_tier": tier, "action_id": None, "alerted": True, "time": times[first],
                           "created_at": times[first]})
            for _ in range(int(rng.integers(0, 4))):
                d = int(rng.integers(first, last + 1))
                events.append({"place_id": pid, "run_id": run_ids[d], "kind": "tier_up", "old_tier": max(tier - 1, 0),
                               "new_tier": tier, "action_id": None, "alerted": True, "time": times[d],
                               "created_at": times[d]})
            if st != "open":
                status.append({"place_id": pid, "by": "eng", "at": times[last], "old": "open", "new": st,
                               "comment": "bench"})
            if rng.random() < 0.1:
                links.append({"place_id": pid, "action_id": int(rng.integers(1, 10)), "relation": "linked",
                              "kind": "tamping", "date": times[last].date(), "km_from": start / 1000,
                              "km_to": (start + length) / 1000})
        s.execute(insert(Place), places)
        for part in _chunks(obs):
            s.execute(insert(PlaceObservation), part)
        s.execute(insert(PlaceEventRow), events)
        if status:
            s.execute(insert(PlaceStatusChange), status)
        if links:
            s.execute(insert(PlaceAction), links)
    longest = max(places, key=lambda p: p["runs_confirming"])
    return {"places": len(places), "listed_open": sum(p["listed"] and p["active"] and p["status"] not in
                                                      ("fixed", "false_alarm") for p in places),
            "observations": len(obs), "events": len(events), "longest": longest["id"],
            "longest_runs": longest["runs_confirming"]}


def _time(fn, repeat: int) -> tuple[float, float]:
    """(first call, median of the next ``repeat``), s."""
    t = time.perf_counter()
    fn()
    first = time.perf_counter() - t
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return first, statistics.median(ts)


def measure(url: str, n_places: int, repeat: int, tmp: Path) -> dict:
    from fastapi.testclient import TestClient

    from app.main import create_app
    from tests.api.support import auth_headers, create_api_key, make_settings

    migrate.upgrade(url)
    db = Database(url)
    t = time.perf_counter()
    made = generate(db, n_places)
    gen_s = time.perf_counter() - t
    db.dispose()
    settings = make_settings(tmp, database_url=url)
    key = create_api_key(url, "engineer", "bench")
    out = {"generated": made, "generate_s": round(gen_s, 1)}
    with TestClient(create_app(settings), headers=auth_headers(key)) as c:
        api = "/api/v1/condition/places"
        t = time.perf_counter()
        assert c.get("/api/v1/condition/lines").status_code == 200  # the app's first request (key check, pools)
        out["app's first request (/condition/lines)"] = {"first_s": round(time.perf_counter() - t, 3),
                                                          "median_s": float("nan")}

        def page():
            r = c.get(api, params={"line_id": LINE})
            assert r.status_code == 200 and len(r.json()["items"]) == min(100, made["listed_open"]), r.text[:300]

        def csv_all():
            r = c.get(f"{api}.csv", params={"line_id": LINE, "limit": 1000})
            assert r.status_code == 200 and r.text.count("\n") == made["listed_open"] + 1

        def history():
            r = c.get(f"{api}/{made['longest']}")
            assert r.status_code == 200 and len(r.json()["observations"]) == made["longest_runs"]

        n = [0]

        def patch():
            n[0] += 1
            r = c.patch(f"{api}/{made['longest']}/status", json={"status": "acknowledged" if n[0] % 2 else "planned",
                                                                 "comment": f"bench {n[0]}"})
            assert r.status_code == 200, r.text

        for name, fn in (("work list, first page", page), ("work list CSV, every open place", csv_all),
                         ("a place's history (longest)", history), ("status change (audited)", patch)):
            first, med = _time(fn, repeat)
            out[name] = {"first_s": round(first, 3), "median_s": round(med, 3)}
    return out


def measure_update(url: str, n_history: int) -> dict:
    """What the publish step's places update adds to a run: a generated 50 km fleet line
    (:func:`app.condition.fleet.ingest_fleet`, daily runs), the first ``n_history`` runs marked applied
    (no places: the history the step reads), then the next run applied through
    :func:`app.places.update.update_places` as the publish step does."""
    from sqlalchemy import select

    from app.condition.fleet import ingest_fleet
    from app.db.models import ConditionRun
    from app.places.index import method_version
    from app.places.update import update_places
    from app.simulate.fleet import FleetSimulator
    from app.simulate.track import generate_line

    migrate.upgrade(url)
    db = Database(url)
    t = time.perf_counter()
    sim = FleetSimulator(generate_line(0.0, KM * 1000.0, seed=5))
    ingest_fleet(db, sim, n_history + 1, line_id="U50", start=START, seed=6, reference=False)
    ingest_s = time.perf_counter() - t
    with db.write() as s:
        runs = s.execute(select(ConditionRun).order_by(ConditionRun.run_time)).scalars().all()
        from app.db.models import Job

        version = method_version(s.get(Job, runs[0].job_id).settings)
        s.execute(insert(PlaceRun), [{"run_id": r.run_id, "line_key": r.line_key, "run_time": r.run_time,
                                      "method_version": version, "start_m": 0.0, "end_m": KM * 1000,
                                      "n_places": 0, "n_events": 0, "applied_at": r.run_time} for r in runs[:-1]])
    last = runs[-1]
    t = time.perf_counter()
    with db.write() as s:
        line = s.get(ConditionLine, last.line_key)
        up = update_places(s, last.run_id, line, last.job_id)
    upd_s = time.perf_counter() - t
    db.dispose()
    assert up.applied, up.reason
    return {"ingest_s": round(ingest_s, 1), "history_runs": n_history, "update_s": round(upd_s, 2),
            "places_found": up.n_found}


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--db", choices=("sqlite", "postgresql", "both", "none"), default="both")
    ap.add_argument("--places", type=int, default=1500)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--update", type=int, default=0, metavar="N",
                    help="also time the publish step's places update of a 50 km run with N history runs (SQLite)")
    args = ap.parse_args(argv)
    results = {}
    if args.update:
        with tempfile.TemporaryDirectory() as tmp:
            print("== publish step's places update, SQLite, 50 km:",
                  measure_update(f"sqlite:///{Path(tmp) / 'update.sqlite'}", args.update))
    with tempfile.TemporaryDirectory() as tmp:
        if args.db in ("sqlite", "both"):
            results["sqlite"] = measure(f"sqlite:///{Path(tmp) / 'bench.sqlite'}", args.places, args.repeat,
                                        Path(tmp))
        if args.db in ("postgresql", "both"):
            from tests.pg_cluster import PgCluster

            cluster = PgCluster().init()
            try:
                results["postgresql"] = measure(cluster.create_database(), args.places, args.repeat, Path(tmp))
            finally:
                cluster.destroy()
    for backend, res in results.items():
        print(f"== {backend}: {res.pop('generated')} (written in {res.pop('generate_s')} s)")
        for name, r in res.items():
            print(f"  {name:38s} first {r['first_s']:.3f} s   median {r['median_s']:.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
