"""Display decimation of a long profile: GET /runs/{id}/profile with max_points.

A synthetic 100 km run (400 000 bins of 25 cm per wheel, four wheels) is stored in a fresh
SQLite database; the stiffness-map page's requests are timed through the ASGI app:
the whole run (max_points=3000 per wheel) and zooms to 10 km and 1 km.

    python bench/bench_profile_display.py [--km 100]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--km", type=float, default=100.0, help="run length, km")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    from fastapi.testclient import TestClient

    from app.core.config import Settings
    from app.db import auth_crud, crud, migrate, results_writer
    from app.db.models import Run
    from app.db.session import Database
    from app.main import create_app

    tmp = Path(tempfile.mkdtemp(prefix="bench-profile-"))
    settings = Settings(_env_file=None, database_url=f"sqlite:///{tmp / 'db.sqlite'}",
                        run_store=tmp / "runs", log_level="WARNING")
    migrate.upgrade(settings.database_url)
    n = int(args.km * 4000)
    rng = np.random.default_rng(0)
    frames = []
    for wheel in ("11", "12", "41", "42"):
        b = np.arange(n, dtype=np.int64)
        frames.append(pd.DataFrame({
            "wheel": wheel, "bin": b, "km": (b + 0.5) * 0.25 / 1000, "n_samples": 125,
            "speed_mean": 30.0, "sleeper_amp": rng.lognormal(0, 0.4, n),
            "sleeper_2_amp": rng.lognormal(-1, 0.4, n), "sleeper_3_amp": rng.lognormal(-1.5, 0.4, n),
            "sleeper_rms": rng.lognormal(-0.3, 0.4, n),
            **{f"order_amp_{i:02d}": rng.random(n) for i in range(1, 12)},
            "residual_rms": 0.3, "sleeper_force_amp": rng.random(n),
        }))
    profiles = pd.concat(frames, ignore_index=True)
    db = Database(settings.database_url)
    t0 = time.perf_counter()
    with db.write() as session:
        run = Run(sha256="0" * 64, file_path="1/run.h5", source_format="hdf5", size_bytes=0, fs=24000.0,
                  n_samples=1, duration_s=1.0, channels=[], meta={}, vehicle_id="BENCH", line_id="B",
                  track="1", km_start=0.0, km_increasing=True)
        session.add(run)
        session.flush()
        job = crud.create_job(session, run.id, {"bin_length_m": 0.25})
        job.status = "done"
        # as the worker does (app.db.queue.complete_job): store, then publish with the job done
        results_writer.store_profile_rows(session, run.id, job.id, profiles)
        results_writer.publish_results(session, run.id, job.id, [])
        run_id = run.id
    with db.write() as session:
        _, api_key = auth_crud.create_api_key(session, "bench", "viewer", created_by="bench")
    db.dispose()
    print(f"stored {len(profiles)} rows in {time.perf_counter() - t0:.1f} s")

    with TestClient(create_app(settings), headers={"Authorization": f"Bearer {api_key}"}) as client:
        cases = [("whole run", None, None, {}), ("10 km", 40.0, 50.0, {}), ("1 km", 45.0, 46.0, {}),
                 ("100 m", 45.0, 45.1, {}),
                 ("whole run, the map's columns", None, None, {"columns": "sleeper_amp,speed_mean,sleeper_force_amp"}),
                 ("line view: whole run in 100 m segments, all columns", None, None, {"level": 100, "max_points": None}),
                 ("line view: whole run in 100 m segments, sleeper_amp", None, None,
                  {"level": 100, "max_points": None, "columns": "sleeper_amp"}),
                 ("line view: whole run in 10 m segments, all columns", None, None, {"level": 10}),
                 ("line view: whole run in 10 m segments, sleeper_amp", None, None,
                  {"level": 10, "columns": "sleeper_amp"})]
        print("| view | rows per wheel in range | rows returned per wheel | median s per wheel | bytes per wheel |")
        print("|---|---|---|---|---|")
        for name, a, b, extra in cases:
            times = []
            for _ in range(args.repeat):
                t = time.perf_counter()
                params = {k: v for k, v in {"wheel": "12", "max_points": 3000, **extra}.items() if v is not None}
                if a is not None:
                    params.update(km_from=a, km_to=b)
                r = client.get(f"/api/v1/runs/{run_id}/profile", params=params)
                times.append(time.perf_counter() - t)
            r.raise_for_status()
            body = r.json()
            print(f"| {name} | {int(((b or args.km) - (a or 0.0)) * 4000)} | {body['n_rows']} | {statistics.median(times):.3f} | {len(r.content)} |")


if __name__ == "__main__":
    main()
