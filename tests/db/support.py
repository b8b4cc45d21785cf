"""Rows for the db layer's tests: runs and profile tables as the pipeline makes them."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from app.db.models import ORDER_COLUMNS, Run, utcnow
from app.db.session import Database

__all__ = ["add_run", "profile_table"]


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
        }))
    return pd.concat(frames, ignore_index=True)
