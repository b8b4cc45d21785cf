"""Condition store at line scale: a year of daily runs over a 50 km line, on SQLite or PostgreSQL.

1. Ingest: ``trackvkf simulate-fleet``'s writer (:func:`app.condition.fleet.ingest_fleet`)
   writes 365 generated runs (4 wheels, 10 m and 100 m segments, change tests, flags);
   wall time, time inside database transactions, rows, bytes per run-km.
2. Detection on that history, scored against the planted changes
   (:class:`app.simulate.fleet_scoring.FleetScorer`): unchanged places flagged, planted 20 % / 20 m
   steps found, days until each planted 10 %/year trend is flagged.
3. Queries through the ASGI app (median of ``--repeat``): the heat map runs × km (100 m, mean
   over the wheels, and one wheel), one segment's trend over the year, the maintenance effect of the
   line's actions, the change list of the newest run, a page of the flag feed.
4. Publishing one more run of the line: the condition part of the publish transaction
   (:func:`app.condition.writer.store_run_condition` on its 25 cm rows, history read from
   the store).

Usage::

    .venv/bin/python bench/bench_condition.py --db sqlite [--km 50 --runs 365]
    .venv/bin/python bench/bench_condition.py --db postgresql   # throw-away cluster (tests/pg_cluster.py)
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _size_bytes(db, url: str, sqlite_path: Path | None) -> dict[str, int]:
    from sqlalchemy import text

    if sqlite_path is not None:
        with db.read() as s:
            rows = s.execute(text(
                "SELECT name, SUM(pgsize) FROM dbstat WHERE name LIKE '%segment_condition%' "
                "OR name LIKE '%condition_flags%' OR name LIKE '%condition_overview%' GROUP BY name")).all()
        return {name: int(size) for name, size in rows}
    with db.read() as s:
        return {t: int(s.execute(text(f"SELECT pg_total_relation_size('{t}')")).scalar())
                for t in ("segment_condition", "condition_overview", "condition_flags")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--db", choices=["sqlite", "postgresql"], default="sqlite")
    ap.add_argument("--km", type=float, default=50.0)
    ap.add_argument("--runs", type=int, default=365)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()

    from fastapi.testclient import TestClient

    from app.condition.config import ConditionConfig
    from app.condition.fleet import ingest_fleet
    from app.condition.writer import store_run_condition
    from app.db import migrate
    from app.db.models import ConditionLine, Job, JobStatus, Run, utcnow
    from app.db.session import Database
    from app.main import create_app
    from app.settings import Settings
    from app.simulate.fleet import FleetSimulator, random_plan
    from app.simulate.fleet_scoring import FleetScorer
    from app.simulate.track import generate_line

    tmp = Path(tempfile.mkdtemp(prefix="bench-condition-"))
    cluster = None
    sqlite_path = None
    if args.db == "sqlite":
        sqlite_path = tmp / "db.sqlite"
        url = f"sqlite:///{sqlite_path}"
    else:
        from tests.pg_cluster import PgCluster

        cluster = PgCluster().init()
        url = cluster.create_database()
    try:
        migrate.upgrade(url)
        db = Database(url)
        length_m = args.km * 1000.0
        line = generate_line(0.0, length_m, seed=args.seed)
        plan = random_plan(0.0, length_m, args.runs, seed=args.seed + 1, n_steps=round(args.km / 2),
                           n_trends=round(args.km / 10), n_actions=round(args.km / 5))
        sim = FleetSimulator(line, plan)
        scorer = FleetScorer(plan)
        start = dt.datetime(2025, 1, 1, 8, 0, tzinfo=dt.UTC)
        print(f"{args.db}: {args.km:g} km, {args.runs} daily runs, 4 wheels; planted {len(plan.steps)} steps, "
              f"{len(plan.trends)} trends, {len(plan.actions)} tamping actions", flush=True)
        cpu0 = _cpu()

        def progress(done: int, total: int) -> None:
            if done % 50 == 0:
                print(f"  {done}/{total} runs", flush=True)

        res = ingest_fleet(db, sim, args.runs, line_id="BENCH", start=start, seed=args.seed,
                           progress=progress, on_run=scorer.add)
        cpu = _cpu() - cpu0
        sizes = _size_bytes(db, url, sqlite_path)
        run_km = args.runs * args.km
        seg_bytes = sum(v for k, v in sizes.items() if "segment_condition" in k or "overview" in k)
        print(f"ingest: {res.runs} runs, {res.segment_rows} segment rows, {res.flags} flags in {res.seconds:.1f} s "
              f"wall ({res.seconds / res.runs:.2f} s/run; {res.write_seconds:.1f} s in transactions), "
              f"{cpu:.1f} s CPU of this process", flush=True)
        print(f"storage: segment and overview rows {seg_bytes / 1e6:.1f} MB with indexes = {seg_bytes / run_km:.0f} bytes per "
              f"run-km ({seg_bytes / res.segment_rows:.0f} bytes per row); {sizes}")
        score = scorer.score()
        print(f"detection: unchanged places flagged {100 * score.false_flag_rate:.3f} % "
              f"({score.unchanged_flagged} of {score.unchanged_tested}), newest run "
              f"{100 * score.newest_unchanged_rate:.3f} %; steps found {score.steps_found}/{score.steps_total}; "
              f"trend delays (days) {[round(d) if np.isfinite(d) else None for d in score.trend_delays_days]}", flush=True)

        settings = Settings(_env_file=None, database_url=url, run_store=tmp / "runs", auth_disabled=True,
                            log_level="WARNING")
        client = TestClient(create_app(settings))

        def timed(label: str, path: str, params: dict) -> None:
            times = []
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                r = client.get(path, params=params)
                times.append(time.perf_counter() - t0)
                assert r.status_code == 200, r.text
            size = len(r.content)
            print(f"| {label} | {statistics.median(times):.3f} | {min(times):.3f} | {size / 1e6:.2f} MB |", flush=True)

        print("| query | median s | min s | answer |\n|---|---|---|---|")
        timed("heat map runs × km, 100 m, mean over wheels", "/api/v1/condition/heatmap", {"line_id": "BENCH"})
        timed("heat map runs × km, 100 m, wheel 12", "/api/v1/condition/heatmap", {"line_id": "BENCH", "wheel": "12"})
        timed("trend of one 10 m segment over the year", "/api/v1/condition/trend",
              {"line_id": "BENCH", "km": args.km / 2 + 0.005})
        timed("trend of one 100 m segment over the year", "/api/v1/condition/trend",
              {"line_id": "BENCH", "km": args.km / 2 + 0.05, "segment_m": 100})
        timed("maintenance effect of every action of the line", "/api/v1/condition/maintenance-effect",
              {"line_id": "BENCH"})
        timed("change list of the newest run", "/api/v1/condition/changes", {"line_id": "BENCH"})
        timed("flag feed, page of 500", "/api/v1/condition/flags", {"since": 0, "limit": 500})
        client.close()

        # one more run published: the condition part of the publish transaction
        _, tracks = sim.run(float(args.runs), np.random.default_rng([args.seed, args.runs]))
        frames = []
        for wheel, t in tracks.items():
            first = np.floor((t.position_m - 0.5) / 0.25).astype(np.int64)  # the 1 m cell's four 25 cm bins
            bins = (first[:, None] + np.arange(4)[None, :]).ravel()
            frames.append(pd.DataFrame({"wheel": wheel, "bin": bins, "speed_mean": np.repeat(t.speed_mps, 4),
                                        "sleeper_amp": np.repeat(t.amplitude, 4)}))
        profiles = pd.concat(frames, ignore_index=True)
        with db.write() as s:
            run = Run(sha256="bench-publish", file_path="x", source_format="hdf5", size_bytes=1, fs=1.0, n_samples=1,
                      duration_s=1.0, channels=[], meta={}, line_id="BENCH", track="1",
                      start_time=start + dt.timedelta(days=args.runs), created_at=utcnow())
            s.add(run)
            s.flush()
            job = Job(run_id=run.id, status=JobStatus.RUNNING, settings={"bin_length_m": 0.25}, created_at=utcnow())
            s.add(job)
            s.flush()
            ids = (run.id, job.id)
        cpu0 = _cpu()
        t0 = time.perf_counter()
        with db.write() as s:
            summary = store_run_condition(s, ids[0], ids[1], config=ConditionConfig.from_settings(settings),
                                          profiles=profiles).summary()
        wall = time.perf_counter() - t0
        print(f"publish of one more {args.km:g} km run ({len(profiles)} bins of 4 wheels, history of "
              f"{summary['history_runs']} runs read from the store): {wall:.2f} s wall, {_cpu() - cpu0:.2f} s CPU; "
              f"{summary['segments']} segment rows, {summary['flags']} flags, shift {summary['shift_m']} m")
        with db.read() as s:
            assert s.query(ConditionLine).count() == 1
        db.dispose()
    finally:
        if cluster is not None:
            cluster.destroy()
    print(f"(pid {os.getpid()}, load average {os.getloadavg()[0]:.1f})")


if __name__ == "__main__":
    main()
