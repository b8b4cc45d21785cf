"""The correlations page's three analyses over the runs of one line, as the page asks them.

Synthetic runs of one line (``--runs`` runs of ``--km`` km, 25 cm bins, four wheels, with force
amplitudes) and its subsidence and maintenance records are stored in a fresh SQLite database;
``GET /analytics/subsidence-fit``, ``/unsprung-mass`` and ``/maintenance`` are then requested at
once (three threads, like the page) through the ASGI app: the first time (nothing cached in the
API process) and again (a second visit, the profile frames of the runs' result jobs cached).

    python bench/bench_correlations.py [--runs 3] [--km 10]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="runs of the line")
    parser.add_argument("--km", type=float, default=10.0, help="length of each run, km")
    args = parser.parse_args()

    from fastapi.testclient import TestClient

    from app.db import auth_crud, crud, migrate, reference_crud, results_writer
    from app.db.models import Run
    from app.db.session import Database
    from app.io.reference import read_reference
    from app.main import create_app
    from app.settings import Settings

    tmp = Path(tempfile.mkdtemp(prefix="bench-corr-"))
    settings = Settings(_env_file=None, database_url=f"sqlite:///{tmp / 'db.sqlite'}",
                        run_store=tmp / "runs", log_level="WARNING")
    migrate.upgrade(settings.database_url)
    n = int(args.km * 4000)
    rng = np.random.default_rng(0)
    db = Database(settings.database_url)
    t0 = time.perf_counter()
    for r in range(args.runs):
        frames = []
        for wheel in ("11", "12", "41", "42"):
            b = np.arange(n, dtype=np.int64)
            amp = rng.lognormal(0.5, 0.4, n)
            frames.append(pd.DataFrame({
                "wheel": wheel, "bin": b, "km": (b + 0.5) * 0.25 / 1000, "n_samples": 125,
                "speed_mean": rng.uniform(20.0, 40.0), "sleeper_amp": amp,
                **{f"order_amp_{i:02d}": rng.random(n) for i in range(1, 12)},
                "residual_rms": 0.3, "sleeper_force_amp": 0.3 * amp * rng.lognormal(0, 0.02, n),
            }))
        profiles = pd.concat(frames, ignore_index=True)
        with db.write() as session:
            run = Run(sha256=f"{r:064d}", file_path=f"{r + 1}/run.h5", source_format="hdf5", size_bytes=0,
                      fs=24000.0, n_samples=1, duration_s=1.0, channels=[], meta={}, vehicle_id="BENCH",
                      line_id="B", track="1", km_start=0.0, km_increasing=True)
            session.add(run)
            session.flush()
            job = crud.create_job(session, run.id, {"bin_length_m": 0.25})
            job.status = "done"
            results_writer.store_profile_rows(session, run.id, job.id, profiles)
            results_writer.publish_results(session, run.id, job.id, [])
    km = np.arange(0.0, args.km, 0.001)
    sub = pd.DataFrame({"line_id": "B", "track": "1", "km": np.repeat(km, 2), "rail": np.tile([1, 2], km.size),
                        "subsidence_mm": rng.normal(-1.5, 0.1, 2 * km.size), "date": "2016-06-01"})
    starts = np.sort(rng.uniform(0, args.km - 0.05, int(args.km * 40)))
    maint = pd.DataFrame({"line_id": "B", "track": "1", "km_from": starts, "km_to": starts + 0.05,
                          "type": "tamping", "date": "2010-05-01"})
    with db.write() as session:
        for kind, frame in (("subsidence", sub), ("maintenance", maint)):
            rows = read_reference(frame.to_csv(index=False).encode(), kind, "csv", f"{kind}.csv")
            reference_crud.insert_reference(session, kind, rows)
        _, api_key = auth_crud.create_api_key(session, "bench", "viewer", created_by="bench")
    db.dispose()
    print(f"stored {args.runs} runs x {4 * n} rows and the reference data in {time.perf_counter() - t0:.1f} s")

    paths = ("subsidence-fit", "unsprung-mass", "maintenance")
    with TestClient(create_app(settings), headers={"Authorization": f"Bearer {api_key}"}) as client:

        def get(path: str) -> float:
            t = time.perf_counter()
            client.get(f"/api/v1/analytics/{path}", params={"line_id": "B", "track": "1"}).raise_for_status()
            return time.perf_counter() - t

        print("| visit | subsidence-fit s | unsprung-mass s | maintenance s | all three at once s |")
        print("|---|---|---|---|---|")
        for visit in ("first", "second"):
            t = time.perf_counter()
            with ThreadPoolExecutor(3) as pool:
                times = list(pool.map(get, paths))
            total = time.perf_counter() - t
            print(f"| {visit} | " + " | ".join(f"{x:.2f}" for x in times) + f" | {total:.2f} |")


if __name__ == "__main__":
    main()
