"""Small hand-made run files (HDF5 and CSV) for upload tests."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pandas as pd

FS = 10_000.0
N = 20_000
ACCEL = ("Z11", "Z12", "Z41", "Z42")


def metadata(**changes: Any) -> dict[str, Any]:
    """Valid run metadata; keys given as ``None`` are removed."""
    md: dict[str, Any] = {
        "vehicle_id": "ICE-1",
        "start_time": "2026-03-02T08:00:00+01:00",
        "line_id": "4010",
        "track": "1",
        "direction": "up",
        "km_start": 12.5,
        "km_increasing": True,
        "sample_rate_hz": FS,
    }
    md.update(changes)
    return {k: v for k, v in md.items() if v is not None}


def channels(n: int = N, seed: int = 0, speed: float = 20.0) -> dict[str, np.ndarray]:
    """Valid channel arrays: four accelerations, constant speed, position."""
    rng = np.random.default_rng(seed)
    data = {c: rng.normal(0.0, 1.0, n).astype(np.float32) for c in ACCEL}
    data["speed"] = np.full(n, speed)
    data["position"] = np.arange(n) * speed / FS
    return data


def write_hdf5(
    path: Path,
    data: dict[str, np.ndarray] | None = None,
    md: dict[str, Any] | None = None,
    fs: float | None = FS,
) -> Path:
    """Write an HDF5 input file: one dataset per channel, attributes for fs and metadata."""
    data = channels() if data is None else data
    md = metadata(sample_rate_hz=None) if md is None else md
    with h5py.File(path, "w") as h5:
        for name, values in data.items():
            h5.create_dataset(name, data=values)
        if fs is not None:
            h5.attrs["sample_rate_hz"] = fs
        h5.attrs["metadata"] = json.dumps(md)
    return path


def write_csv(path: Path, data: dict[str, np.ndarray] | None = None) -> Path:
    """Write a CSV input file, one column per channel."""
    data = channels() if data is None else data
    pd.DataFrame(data).to_csv(path, index=False)
    return path
