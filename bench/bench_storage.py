"""Bytes per run-km of the 25 cm profile rows on SQLite and PostgreSQL (table + indexes).

Stores the rows of ``--runs`` synthetic runs of ``--km`` km (4 wheels, every indicator column
filled, as the pipeline writes them) through the results writer and divides the tables' size by
the run-km. The segment condition rows are measured by ``bench/bench_condition.py``.

Usage: ``.venv/bin/python bench/bench_storage.py [--km 10 --runs 3]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
from sqlalchemy import text

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

def _profiles(km: float, seed: int) -> pd.DataFrame:
    from app.db.models import ORDER_COLUMNS

    rng = np.random.default_rng(seed)
    bins = np.arange(int(km * 4000), dtype=np.int64)
    frames = []
    for wheel in ("11", "12", "41", "42"):
        n = bins.size
        frames.append(pd.DataFrame({
            "wheel": wheel, "bin": bins, "km": (bins + 0.5) * 0.25 / 1000.0, "n_samples": rng.integers(150, 400, n),
            "speed_mean": rng.uniform(25, 45, n), "sleeper_amp": rng.lognormal(0.2, 0.4, n),
            **{c: rng.lognormal(-2, 0.5, n) for c in ORDER_COLUMNS},
            "residual_rms": rng.lognormal(0, 0.2, n), "sleeper_force_amp": rng.lognormal(0.5, 0.3, n),
        }))
    return pd.concat(frames, ignore_index=True)


def _measure(url: str, km: float, runs: int) -> tuple[float, int]:
    from app.db import migrate, partitions, results_writer
    from app.db.models import Job, JobStatus, Run, utcnow
    from app.db.session import Database

    migrate.upgrade(url)
    db = Database(url)
    n_rows = 0
    try:
        for i in range(runs):
            with db.write() as s:
                run = Run(sha256=f"storage-{i}", file_path="x", source_format="hdf5", size_bytes=1, fs=1.0,
                          n_samples=1, duration_s=1.0, channels=[], meta={}, created_at=utcnow())
                s.add(run)
                s.flush()
                job = Job(run_id=run.id, status=JobStatus.DONE, settings={}, created_at=utcnow())
                s.add(job)
                s.flush()
                ids = (run.id, job.id)
            partitions.ensure_for_job(db, ids[1])
            frame = _profiles(km, i)
            with db.write() as s:
                n_rows += results_writer.store_profile_rows(s, ids[0], ids[1], frame)
        with db.read() as s:
            if db.engine.dialect.name == "sqlite":
                s.execute(text("PRAGMA wal_checkpoint(TRUNCATE)"))
                size = s.execute(text("SELECT SUM(pgsize) FROM dbstat WHERE name LIKE '%profile_bins%'")).scalar()
            else:
                s.execute(text("ANALYZE profile_bins"))
                parts = [r[0] for r in s.execute(text(
                    "SELECT c.relname FROM pg_inherits i JOIN pg_class c ON c.oid = i.inhrelid "
                    "WHERE i.inhparent = 'profile_bins'::regclass")).all()] or ["profile_bins"]
                size = sum(s.execute(text(f"SELECT pg_total_relation_size('{p}')")).scalar() for p in parts)
        return float(size), n_rows
    finally:
        db.dispose()

def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--km", type=float, default=10.0)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    from tests.pg_cluster import PgCluster

    tmp = Path(tempfile.mkdtemp(prefix="bench-storage-"))
    run_km = args.km * args.runs
    size, rows = _measure(f"sqlite:///{tmp / 'db.sqlite'}", args.km, args.runs)
    print(f"sqlite: {rows} rows, {size / 1e6:.1f} MB = {size / run_km / 1e6:.2f} MB per run-km "
          f"({size / rows:.0f} bytes per row)")
    cluster = PgCluster().init()
    try:
        size, rows = _measure(cluster.create_database(), args.km, args.runs)
        print(f"postgresql: {rows} rows, {size / 1e6:.1f} MB = {size / run_km / 1e6:.2f} MB per run-km "
              f"({size / rows:.0f} bytes per row)")
    finally:
        cluster.destroy()

if __name__ == "__main__":
    main()
