"""Rows for the db layer's tests: runs and profile tables as the pipeline makes them."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from app.db import crud
from app.db.models import ORDER_COLUMNS, Run, utcnow
from app.db.session import Database

__all__ = ["add_run", "profile_table", "make_run_with_job", "job_results"]


def add_run(db: Database, sha: str = "a" * 64, **columns: Any) -> int:
    """Insert a run row (``columns`` override the defaults); returns its id."""
    values: dict[str, Any] = {
        "sha256": sha, "file_path": "x", "source_format": "hdf5", "size_bytes": 1, "fs": 10_000.0,
        "n_samples": 10, "duration_s": 0.001, "channels": ["Z11"], "meta": {}, "created_at": utcnow(),
    }
    values.update(columns)
    with db.write() as s:
        run = Run(**values)
        s.add(run)
        s.flush()
        return run.id


def profile_table(
    wheels: tuple[str, ...] = ("11", "12"),
    n_bins: int = 50,
    *,
    first_bin: int = 1_000,
    bin_length_m: float = 0.25,
    seed: int = 0,
) -> pd.DataFrame:
    """Profile rows like ``RunResults.profiles``: every indicator column, random values.

    Bin centres lie at ``(bin + 0.5) × bin_length_m``; km grows with the bin.
    """
    rng = np.random.default_rng(seed)
    bins = np.arange(first_bin, first_bin + n_bins, dtype=np.int64)
    frames = []
    for wheel in wheels:
        frames.append(pd.DataFrame({
            "wheel": wheel,
            "bin": bins,
            "km": (bins + 0.5) * bin_length_m / 1000.0,
            "n_samples": rng.integers(50, 150, n_bins),
            "speed_mean": rng.uniform(10.0, 40.0, n_bins),
            "sleeper_amp": rng.lognormal(0.0, 0.5, n_bins),
            "sleeper_2_amp": rng.lognormal(-1.0, 0.5, n_bins),
            "sleeper_3_amp": rng.lognormal(-1.5, 0.5, n_bins),
            "sleeper_rms": rng.lognormal(-0.3, 0.5, n_bins),
            **{c: rng.random(n_bins) for c in ORDER_COLUMNS},
            "residual_rms": rng.random(n_bins),
            "sleeper_force_amp": rng.random(n_bins),
            "sleeper_amp_raw": rng.lognormal(0.2, 0.5, n_bins),
            "sleeper_amp_sd": rng.uniform(0.05, 0.5, n_bins),
            "sleeper_amp_sd_shared": rng.uniform(0.0, 0.05, n_bins),
            # a track impact every 100 bins (NULL elsewhere)
            "track_impact_mm": np.where(bins % 100 == 37, rng.uniform(0.1, 0.5, n_bins), np.nan),
            "sleeper_step": np.where(bins % 400 < 200, 1.2, 0.9),
        }))
    return pd.concat(frames, ignore_index=True)


def make_run_with_job(db: Database, sha: str = "a" * 64) -> tuple[int, int]:
    """A run row and its queued job; (run id, job id)."""
    with db.write() as s:
        run = Run(
            sha256=sha, file_path="x", source_format="hdf5", size_bytes=1, fs=10_000.0,
            n_samples=10, duration_s=0.001, channels=["Z11"], meta={}, created_at=utcnow(),
        )
        s.add(run)
        s.flush()
        job = crud.create_job(s, run.id, {"n_wheel_orders": 11})
        return run.id, job.id


def job_results(n_bins: int, value: float) -> tuple[pd.DataFrame, list[dict]]:
    """Profile rows of wheels 11 and 12 (``n_bins`` bins of amplitude ``value``) and their wheel results."""
    rows = []
    for wheel in ("11", "12"):
        for b in range(n_bins):
            rows.append({"wheel": wheel, "bin": 40_000 + b, "km": (40_000 + b + 0.5) * 0.25 / 1000,
                         "n_samples": 100, "speed_mean": 20.0, "sleeper_amp": value,
                         **{f"order_amp_{i:02d}": value / i for i in range(1, 12)},
                         "residual_rms": 0.1, "sleeper_force_amp": np.nan})
    wheels = [{"wheel": w, "wheel_diameter_m": 0.92, "n_windows": 3,
               "orders": [{"order": 1, "radius_um": 10.0}], "angles_deg": [0.0, 1.0],
               "profile_um": [1.0, np.float64(2.0)], "profile_p05_um": None, "profile_p95_um": None}
              for w in ("11", "12")]
    return pd.DataFrame(rows), wheels
