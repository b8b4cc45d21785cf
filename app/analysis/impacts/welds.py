"""Welds on rough rail: the long filters' evidence combined across the wheels that meet one track position.

A dipped weld is fixed to the track, and so is the rail's random roughness:
the two axles on one rail meet the same roughness, so their scores agree
whether there is a weld or not (averaging them takes out measurement noise and
a vehicle's own jolt, nothing of the roughness). The two rails have
independent roughness, and a weld of a rail pair (the simulator's, the
physics' two-rail runs) dips both: there the scores add as independent
evidence. Per wheel the score is the generalised-least-squares depth of a
dip over its robust spread (:func:`app.analysis.impacts.dips.scan_dips`), a
unit Gaussian over rough rail; hence per track position

    z_side = mean of the side's axles' scores,
    Z = (z_1 + z_2) / sqrt(2)     (both sides measured),

Z a unit Gaussian over roughness alone and ``sqrt(2)`` times one rail's
evidence at a weld pair. How strong that evidence can be is set by the
roughness: the matched filter's depth error over Sato's "good rail" spectrum
(``A / Omega³``, A = 4.15e-8) is about 69 µm for a 1 m dip (35 µm for 0.5 m,
118 µm for 1.6 m), so a 0.3 mm, 1 m weld scores about 4.3 on one rail and 6.1
on a rail pair (docs/indicator.md, welds section, with the measured
distributions). A track impact is a peak of ``Z`` reaching
:data:`PAIR_Z_THRESHOLD`, or of one side's score reaching
:data:`SINGLE_Z_THRESHOLD` (a weld of one rail; the only test when one side is
measured), confirmed, where two axles are measured, by each axle's own
evidence reaching :data:`CONFIRM_THRESHOLD` there (fixed to the track, met by
both axles).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import maximum_filter1d
from scipy.signal import find_peaks

from app.analysis.impacts.classify import TrackImpactFinding
from app.analysis.impacts.dips import MIN_DEPTH_M, SIDE_LOBE_M, SIDE_LOBE_RATIO

__all__ = [
    "PAIR_Z_THRESHOLD",
    "SINGLE_Z_THRESHOLD",
    "CONFIRM_THRESHOLD",
    "GRID_M",
    "WheelTrace",
    "combined_track_dips",
]

#: Combined score of a rail pair, ``(z_1 + z_2) / sqrt 2``, that makes a track impact.
PAIR_Z_THRESHOLD = 4.6
#: One side's score (mean over its axles) that makes a track impact of that rail alone.
SINGLE_Z_THRESHOLD = 5.0
#: With two axles measured, each axle's own evidence there must reach this.
CONFIRM_THRESHOLD = 3.0
#: Track grid on which the wheels' traces are combined, m.
GRID_M = 0.1
#: Position tolerance between wheels (a maximum over ± this), m.
ALIGN_M = 0.15


@dataclass(frozen=True)
class WheelTrace:
    """One wheel's long-filter score trace on the track (:class:`app.analysis.impacts.dips.DipTrace`).

    Attributes
    ----------
    track_m : numpy.ndarray
        Track position, m on the km axis.
    score, length_m, depth_m : numpy.ndarray
        Best score, its length (m) and depth (m) there; NaN score where no dip was sought.
    """

    track_m: np.ndarray
    score: np.ndarray
    length_m: np.ndarray
    depth_m: np.ndarray

    def __post_init__(self) -> None:
        n = np.asarray(self.track_m).shape
        for name in ("track_m", "score", "length_m", "depth_m"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != n or a.ndim != 1:
                raise ValueError(f"{name}: must be 1-D like track_m")
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return int(self.track_m.size)


def _on_grid(tr: WheelTrace, x0: float, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Score, length, depth per grid cell (the best trace point in the cell, then the best within ALIGN_M)."""
    score = np.full(n, -np.inf)
    length = np.zeros(n)
    depth = np.zeros(n)
    ok = np.isfinite(tr.score) & np.isfinite(tr.track_m)
    if not ok.any():
        return np.full(n, np.nan), length, depth
    cell = np.floor((tr.track_m[ok] - x0) / GRID_M).astype(np.int64)
    inside = (cell >= 0) & (cell < n)
    cell, sc = cell[inside], tr.score[ok][inside]
    ln, dp = tr.length_m[ok][inside], tr.depth_m[ok][inside]
    order = np.argsort(sc, kind="stable")  # the best last: it wins the assignment
    score[cell[order]] = sc[order]
    length[cell[order]] = ln[order]
    depth[cell[order]] = dp[order]
    have = np.isfinite(score)
    reach = max(1, int(round(ALIGN_M / GRID_M)))
    pooled = maximum_filter1d(np.where(have, score, -np.inf), size=2 * reach + 1, mode="constant", cval=-np.inf)
    # the length and depth of the pooled maximum: that of the best cell within reach
    idx = np.arange(n)
    best_idx = idx.copy()
    best = np.where(have, score, -np.inf)
    for k in range(1, reach + 1):
        for sh in (k, -k):
            j = np.clip(idx + sh, 0, n - 1)
            better = best[j] > np.where(best_idx == idx, best, best[best_idx])
            best_idx = np.where(better, j, best_idx)
    out = np.where(np.isfinite(pooled), pooled, np.nan)
    return out, length[best_idx], depth[best_idx]


def combined_track_dips(
    traces: Mapping[str, WheelTrace],
    *,
    wheels_measured: tuple[str, ...] | None = None,
    pair_threshold: float = PAIR_Z_THRESHOLD,
    single_threshold: float = SINGLE_Z_THRESHOLD,
    confirm_threshold: float = CONFIRM_THRESHOLD,
) -> list[TrackImpactFinding]:
    """Track impacts from the wheels' long-filter traces (module docstring).

    Parameters
    ----------
    traces : mapping of wheel ("11", "12", "41", "42") to WheelTrace
    wheels_measured : tuple of str, optional
        The wheels the run measured (default those in ``traces``): with two axles, both must confirm.
    pair_threshold, single_threshold, confirm_threshold : float
        See :data:`PAIR_Z_THRESHOLD`, :data:`SINGLE_Z_THRESHOLD`, :data:`CONFIRM_THRESHOLD`.

    Returns
    -------
    list of TrackImpactFinding
        Ascending track position; ``score`` is the combined score ``Z`` (or the side's where one
        side alone carries it).
    """
    if not (pair_threshold > 0 and single_threshold > 0 and confirm_threshold >= 0):
        raise ValueError("pair_threshold, single_threshold: must be > 0; confirm_threshold: >= 0")
    for wheel in traces:
        if len(wheel) != 2 or wheel[1] not in "12":
            raise ValueError(f"traces: wheel ids are axle + side ('11' … '42'), got {wheel!r}")
    live = {w: t for w, t in traces.items() if len(t) and np.isfinite(t.score).any()}
    if not live:
        return []
    lo = min(float(np.nanmin(t.track_m)) for t in live.values())
    hi = max(float(np.nanmax(t.track_m)) for t in live.values())
    n = int(math.floor((hi - lo) / GRID_M)) + 1
    grid = {w: _on_grid(t, lo, n) for w, t in live.items()}
    axles_measured = sorted({w[0] for w in (traces if wheels_measured is None else wheels_measured)})

    def mean_of(wheels: list[str], k: int) -> np.ndarray:
        stack = np.vstack([grid[w][k] for w in wheels]) if wheels else np.full((1, n), np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: NaN
            return np.nanmean(stack, axis=0)

    side_z: dict[int, np.ndarray] = {}
    side_d: dict[int, np.ndarray] = {}
    for side in (1, 2):
        mine = [w for w in live if int(w[1]) == side]
        if mine:
            side_z[side], side_d[side] = mean_of(mine, 0), mean_of(mine, 2)
    zs = np.vstack(list(side_z.values()))
    count = np.sum(np.isfinite(zs), axis=0)
    total = np.nansum(zs, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        pair = np.where(count >= 2, total / np.sqrt(np.maximum(count, 1)), np.nan)
        best_side = np.nanmax(np.where(np.isfinite(zs), zs, -np.inf), axis=0)
    # one statistic on one scale: a pair's Z over its threshold, or a side's over its own
    merit = np.fmax(np.where(np.isfinite(pair), pair / pair_threshold, -np.inf), best_side / single_threshold)
    merit = np.where(np.isfinite(merit), merit, -np.inf)
    peaks, _ = find_peaks(np.where(np.isfinite(merit), merit, -1e300), height=1.0,
                          distance=max(1, int(1.5 / GRID_M)))
    if peaks.size == 0:
        return []
    # side lobes of a strong dip (the whitened filters' answer a metre or two either side)
    order = peaks[np.argsort(-merit[peaks], kind="stable")]
    kept: list[int] = []
    reach = SIDE_LOBE_M / GRID_M
    for p in order:
        if not any(abs(p - k) <= reach and merit[k] >= SIDE_LOBE_RATIO * merit[p] for k in kept):
            kept.append(int(p))
    out: list[TrackImpactFinding] = []
    x = lo + (np.arange(n) + 0.5) * GRID_M
    for p in sorted(kept):
        if len(axles_measured) >= 2:
            axle_ok = []
            for axle in axles_measured:
                mine = [w for w in live if w[0] == axle and np.isfinite(grid[w][0][p])]
                if not mine:
                    axle_ok.append(False)
                    continue
                z_axle = sum(grid[w][0][p] for w in mine) / math.sqrt(len(mine))
                axle_ok.append(z_axle >= confirm_threshold)
            if not all(axle_ok):
                continue
        depth_by_side = {s: float(side_d[s][p]) for s in side_z if np.isfinite(side_z[s][p])}
        depths = [d for d in depth_by_side.values() if np.isfinite(d)]
        if not depths or float(np.mean(depths)) < MIN_DEPTH_M:
            continue
        wheels = tuple(sorted(w for w in live if np.isfinite(grid[w][0][p])))
        top = max(wheels, key=lambda w: grid[w][0][p])
        score = float(pair[p]) if np.isfinite(pair[p]) and pair[p] / pair_threshold >= best_side[p] / single_threshold \
            else float(best_side[p])
        out.append(TrackImpactFinding(track_m=float(x[p]), length_m=float(grid[top][1][p]),
                                      depth_m=float(np.mean(depths)), depth_by_side=depth_by_side,
                                      wheels=wheels, score=score))
    return out
