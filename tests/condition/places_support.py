"""Synthetic truth of the places tests: a 3 km line's speed-conditioned index per 10 m segment and
wheel, run after run (its own smooth natural variation, a level per run, per-segment noise)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from app.analysis.condition.run_places import PlaceParams
from app.analysis.condition.tiers import TierLimits, TierTable

PARAMS = PlaceParams(TierTable(TierLimits(0.25, 0.375, 0.625), {"slab": TierLimits(0.2, 0.3, 0.5)}),
                     TierLimits(0.10, 0.30, 0.50))
SEG = np.arange(1000, 1300)  # 3 km of 10 m segments: km 10–13
W = 4
NOISE = 0.02  # run-to-run repeatability of a 10 m segment, ln units
COVERED = (10_000.0, 13_000.0)


def track(rng: np.random.Generator) -> np.ndarray:
    """A line's own index per segment: smooth natural variation, |x| < 0.15."""
    x = np.convolve(rng.normal(0, 0.05, SEG.size + 4), np.ones(5) / np.sqrt(5), mode="valid")
    return np.clip(x, -0.15, 0.15)


def runs(rng: np.random.Generator, base: np.ndarray, n: int,
         extra: Callable[[int], np.ndarray] | None = None) -> np.ndarray:
    """(W, S, n) index of n runs: ``base`` + a level per run + noise (+ ``extra(run)``)."""
    out = np.empty((W, SEG.size, n))
    for r in range(n):
        out[:, :, r] = base[None, :] + rng.normal(0, 0.01) + rng.normal(0, NOISE, (W, SEG.size))
        if extra is not None:
            out[:, :, r] += extra(r)[None, :]
    return out


def box(a_m: float, b_m: float, size: float) -> np.ndarray:
    """``size`` over ``[a_m, b_m)`` as the segments' means (exact partial coverage)."""
    lo, hi = SEG * 10.0, (SEG + 1) * 10.0
    return size * np.clip(np.minimum(hi, b_m) - np.maximum(lo, a_m), 0, None) / 10.0
