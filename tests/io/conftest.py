"""Shared helpers of the run-file tests."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

FS = 2000.0


def base_meta(**over: Any) -> dict[str, Any]:
    """A valid metadata dict (no sample rate)."""
    meta: dict[str, Any] = {
        "vehicle_id": "V-7",
        "start_time": "2024-05-01T08:00:00+02:00",
        "line_id": "4711",
        "track": "1",
        "direction": "up",
        "km_start": 10.0,
        "km_increasing": True,
    }
    meta.update(over)
    return meta


def kinematic_arrays(
    n: int, fs: float = FS, v0: float = 20.0, acc: float = 0.5
) -> dict[str, np.ndarray]:
    """Speed (m/s) and position (m) of a uniformly accelerated run, plus a Z11 signal."""
    t = np.arange(n) / fs
    rng = np.random.default_rng(1)
    return {
        "Z11": np.sin(2 * np.pi * 37.0 * t) + 0.1 * rng.standard_normal(n),
        "Z42": np.cos(2 * np.pi * 11.0 * t),
        "speed": v0 + acc * t,
        "position": 100.0 + v0 * t + 0.5 * acc * t**2,
    }


def listing(directory: Path) -> list[str]:
    """Names in a directory (to check that nothing was left behind)."""
    return sorted(p.name for p in directory.iterdir())


@pytest.fixture
def out_dir(tmp_path: Path) -> Path:
    """An empty output directory."""
    d = tmp_path / "out"
    d.mkdir()
    return d
