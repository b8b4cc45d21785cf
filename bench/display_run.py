"""A synthetic long run with stored profiles, for the display benchmarks.

``store_display_run`` writes a run of ``km`` kilometres (400 000 bins of 25 cm per 100 km and
wheel, four wheels, every indicator column) and its done job into a migrated database, as the
worker does (store the rows, then publish), and creates a viewer API key.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["WHEELS", "store_display_run"]

WHEELS = ("11", "12", "41", "42")


def _profiles(km: float, seed: int = 0) -> pd.DataFrame:
    n = int(km * 4000)
    rng = np.random.default_rng(seed)
    frames = []
    for wheel in WHEELS:
        b = np.arange(n, dtype=np.int64)
        frames.append(pd.DataFrame({
            "wheel": wheel, "bin": b, "km": (b + 0.5) * 0.25 / 1000, "n_samples": 125,
            "speed_mean": 30.0, "sleeper_amp": rng.lognormal(0, 0.4, n),
            "sleeper_2_amp": rng.lognormal(-1, 0.4, n), "sleeper_3_amp": rng.lognormal(-1.5, 0.4, n),
            "sleeper_rms": rng.lognormal(-0.3, 0.4, n),
            **{f"order_amp_{i:02d}": rng.random(n) for i in range(1, 12)},
            "residual_rms": 0.3, "sleeper_force_amp": rng.random(n),
        }))
    return pd.concat(frames, ignore_index=True)


def store_display_run(database_url: str, km: float) -> tuple[int, str, int]:
    """Store a ``km`` long run with a done job; returns (run id, viewer API key, rows stored)."""
    from app.db import auth_crud, crud, results_writer
    from app.db.models import Run
    from app.db.session import Database

    profiles = _profiles(km)
    db = Database(database_url)
    try:
        with db.write() as session:
            run = Run(sha256="0" * 64, file_path="1/run.h5", source_format="hdf5", size_bytes=0, fs=24000.0,
                      n_samples=1, duration_s=1.0, channels=[], meta={}, vehicle_id="BENCH", line_id="B",
                      track="1", km_start=0.0, km_increasing=True)
            session.add(run)
            session.flush()
            job = crud.create_job(session, run.id, {"bin_length_m": 0.25})
            job.status = "done"
            # as the worker does (app.publish.publish_job): store, then publish with the job done
            results_writer.store_profile_rows(session, run.id, job.id, profiles)
            results_writer.publish_results(session, run.id, job.id, [])
            run_id = run.id
        with db.write() as session:
            _, api_key = auth_crud.create_api_key(session, "bench", "viewer", created_by="bench")
    finally:
        db.dispose()
    return run_id, api_key, len(profiles)
