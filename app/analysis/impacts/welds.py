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

#: Combined score of a rail pair, ``(z_1 + z_2) / sqrt 2``, that makes a track impact: set by the
#: roughness's own peaks (a unit Gaussian's, ~1000 independent values per km and length: about 0.5
#: per km reach 4.0; measured 0.47 per km on 23.6 km of simulated rough rail, docs/indicator.md).
PAIR_Z_THRESHOLD = 4.0
#: One side's score (mean over its axles) that makes a track impact of that rail alone (one rail's
#: roughness peaks reach 5.0 about 0.1 per km).
SINGLE_Z_THRESHOLD = 5.0
#: With two axles measured, each axle's own evidence there must reach this.
CONFIRM_THRESHOLD = 3.0
#: Track grid on which the wheels' traces are combined (interpolated), m.
GRID_M = 0.04
#: A grid cell farther than this from a wheel's trace sample has no value of that wheel, m.
MAX_GAP_M = 0.2


@dataclass(frozen=True)
class WheelTrace:
    """One wheel's long-filter scores on the track, per length (:class:`app.analysis.impacts.dips.DipTrace`).

    Attributes
    ----------
    track_m : numpy.ndarray
        Track position, m on the km axis, shape (m,).
    lengths_m : numpy.ndarray
        The filters' dip lengths, m, shape (k,).
    score, depth_m : numpy.ndarray
        Score and depth (m) per length there, shape (k, m); NaN score where no dip was sought.
    """

    track_m: np.ndarray
    lengths_m: np.ndarray
    score: np.ndarray
    depth_m: np.ndarray

    def __post_init__(self) -> None:
        x = np.asarray(self.track_m, dtype=np.float64)
        ln = np.asarray(self.lengths_m, dtype=np.float64).reshape(-1)
        if x.ndim != 1:
            raise ValueError("track_m: must be 1-D")
        object.__setattr__(self, "track_m", x)
        object.__setattr__(self, "lengths_m", ln)
        for name in ("score", "depth_m"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != (ln.size, x.size):
                raise ValueError(f"{name}: must have shape (len(lengths_m), len(track_m))")
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return int(self.track_m.size)


def _on_grid(x: np.ndarray, score: np.ndarray, depth: np.ndarray, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Score and depth interpolated onto the grid (NaN farther than :data:`MAX_GAP_M` from a sample)."""
    ok = np.isfinite(score) & np.isfinite(x)
    if ok.sum() < 2:
        return np.full(grid.size, np.nan), np.full(grid.size, np.nan)
    xs, sc, dp = x[ok], score[ok], depth[ok]
    order = np.argsort(xs, kind="stable")
    xs, sc, dp = xs[order], sc[order], dp[order]
    j = np.clip(np.searchsorted(xs, grid), 1, xs.size - 1)
    gap = np.minimum(np.abs(grid - xs[j - 1]), np.abs(xs[j] - grid))
    far = gap > MAX_GAP_M
    return (np.where(far, np.nan, np.interp(grid, xs, sc)), np.where(far, np.nan, np.interp(grid, xs, dp)))


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
    lengths = next(iter(live.values())).lengths_m
    if any(not np.array_equal(t.lengths_m, lengths) for t in live.values()):
        raise ValueError("traces: every wheel's trace must have the same lengths_m")
    lo = min(float(np.nanmin(t.track_m)) for t in live.values())
    hi = max(float(np.nanmax(t.track_m)) for t in live.values())
    n = int(math.floor((hi - lo) / GRID_M)) + 1
    x = lo + np.arange(n) * GRID_M
    axles_measured = sorted({w[0] for w in (traces if wheels_measured is None else wheels_measured)})
    # per length: every wheel's score on the grid, the sides' means, the pair's sum / sqrt 2
    merit = np.full(n, -np.inf)
    best_k = np.zeros(n, dtype=np.int64)
    grids: list[dict[str, tuple[np.ndarray, np.ndarray]]] = []
    for k in range(lengths.size):
        g = {w: _on_grid(t.track_m, t.score[k], t.depth_m[k], x) for w, t in live.items()}
        grids.append(g)
        zs = []
        for side in (1, 2):
            mine = [w for w in live if int(w[1]) == side]
            if mine:
                zs.append(_nanmean(np.vstack([g[w][0] for w in mine])))
        z = np.vstack(zs)
        count = np.sum(np.isfinite(z), axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            pair = np.where(count >= 2, np.nansum(z, axis=0) / np.sqrt(np.maximum(count, 1)), -np.inf)
        side_best = np.max(np.where(np.isfinite(z), z, -np.inf), axis=0)
        # one statistic on one scale: a pair's Z over its threshold, or a side's over its own
        m_k = np.maximum(pair / pair_threshold, side_best / single_threshold)
        better = m_k > merit
        merit = np.where(better, m_k, merit)
        best_k = np.where(better, k, best_k)
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
    for p in sorted(kept):
        k = int(best_k[p])
        g = grids[k]
        if len(axles_measured) >= 2:
            axle_ok = []
            for axle in axles_measured:
                mine = [w for w in live if w[0] == axle and np.isfinite(g[w][0][p])]
                z_axle = sum(g[w][0][p] for w in mine) / math.sqrt(len(mine)) if mine else -np.inf
                axle_ok.append(z_axle >= confirm_threshold)
            if not all(axle_ok):
                continue
        depth_by_side: dict[int, float] = {}
        side_z: list[float] = []
        for side in (1, 2):
            mine = [w for w in live if int(w[1]) == side and np.isfinite(g[w][0][p])]
            if mine:
                depth_by_side[side] = float(np.mean([g[w][1][p] for w in mine]))
                side_z.append(float(np.mean([g[w][0][p] for w in mine])))
        if not depth_by_side or float(np.mean(list(depth_by_side.values()))) < MIN_DEPTH_M:
            continue
        pair_z = sum(side_z) / math.sqrt(len(side_z)) if len(side_z) >= 2 else -np.inf
        score = pair_z if pair_z / pair_threshold >= max(side_z) / single_threshold else max(side_z)
        out.append(TrackImpactFinding(track_m=float(x[p]), length_m=float(lengths[k]),
                                      depth_m=float(np.mean(list(depth_by_side.values()))),
                                      depth_by_side=depth_by_side,
                                      wheels=tuple(sorted(w for w in live if np.isfinite(g[w][0][p]))),
                                      score=float(score)))
    return out


def _nanmean(stack: np.ndarray) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: NaN
        return np.nanmean(stack, axis=0)
