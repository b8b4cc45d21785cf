"""Telling track impacts from wheel flats: where the dips of the wheels repeat.

The dips found under each wheel (:func:`app.analysis.impacts.dips.find_dips`)
are of three kinds, and their positions say which:

* **Wheel flat** — fixed to one wheel: it meets the rail once per revolution,
  so that wheel's dips repeat every circumference ``pi d`` of its own
  travelled distance (:func:`wheel_flats`), and no other wheel's do.
* **Track impact** (dipped weld or joint) — fixed to the track: every wheel
  meets it at the same track position, the trailing axle later than the
  leading one (:func:`track_impacts`). The two rails' welds of a weld pair
  lie at the same position; each rail has its own roughness, so their
  scores add as independent evidence, while the two axles on one rail meet
  the same roughness and only confirm that the dip is fixed to the track.
* **Roughness** — the rest: random, fixed to the track too, but not
  standing out (the scores' spread is the roughness's own).

Scores are depths over their robust spread; :data:`CANDIDATE_THRESHOLD` keeps
a wheel's dips, a track impact needs :data:`PAIR_THRESHOLD` summed over both
rails or :data:`SINGLE_RAIL_THRESHOLD` on one, a flat :data:`FLAT_MIN_HITS`
dips one circumference apart.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from app.analysis.impacts.dips import DETECTION_THRESHOLD as CANDIDATE_THRESHOLD
from app.analysis.impacts.dips import MIN_DEPTH_M

__all__ = [
    "CANDIDATE_THRESHOLD",
    "PAIR_THRESHOLD",
    "SINGLE_RAIL_THRESHOLD",
    "FLAT_MIN_HITS",
    "MIN_DEPTH_M",
    "WheelDips",
    "TrackImpactFinding",
    "WheelFlatFinding",
    "wheel_flats",
    "track_impacts",
    "one_per_dip",
]

#: Sum over the two rails of their scores that makes a track impact seen on both rails.
PAIR_THRESHOLD = 8.0
#: Score on one rail that makes a track impact of that rail alone.
SINGLE_RAIL_THRESHOLD = 6.5
#: Dips one circumference apart (chained) that make a wheel flat.
FLAT_MIN_HITS = 5
#: Two dips of different wheels are at the same track position within this (plus half the dip length), m.
POSITION_TOL_M = 0.4
#: A flat's dips repeat within this of one circumference, m.
FLAT_TOL_M = 0.03
#: Two track impacts closer than this are one dip and its ringing, m (:func:`one_per_dip`).
ONE_DIP_M = 3.0


@dataclass(frozen=True)
class WheelDips:
    """The dips of one wheel over a run (one entry per dip).

    Attributes
    ----------
    track_m : numpy.ndarray
        Track position, m on the km axis.
    s_m : numpy.ndarray
        The wheel's travelled distance (the run's phase reference), m.
    length_m, depth_m, score, speed_mps : numpy.ndarray
        Of the matched dip (:class:`~app.analysis.impacts.dips.Dips`).
    """

    track_m: np.ndarray
    s_m: np.ndarray
    length_m: np.ndarray
    depth_m: np.ndarray
    score: np.ndarray
    speed_mps: np.ndarray

    def __post_init__(self) -> None:
        n = np.asarray(self.track_m).shape
        for name in ("track_m", "s_m", "length_m", "depth_m", "score", "speed_mps"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != n or a.ndim != 1:
                raise ValueError(f"{name}: must be 1-D like track_m")
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return int(self.track_m.size)

    def take(self, mask: np.ndarray) -> WheelDips:
        """The dips where ``mask`` is true."""
        return WheelDips(*(getattr(self, f)[mask] for f in ("track_m", "s_m", "length_m", "depth_m", "score",
                                                            "speed_mps")))


@dataclass(frozen=True)
class TrackImpactFinding:
    """An isolated impact fixed to the track (a dipped weld or joint).

    Attributes
    ----------
    track_m : float
        Position, m on the km axis (mean over the wheels that met it).
    length_m : float
        Length of the best matched dip, m.
    depth_m : float
        Estimated depth, m (mean over the rails it was found on).
    depth_by_side : dict
        Estimated depth per rail side (1 right, 2 left) where found, m.
    wheels : tuple of str
        Wheels whose dips make it.
    score : float
        Evidence: the rails' scores summed.
    """

    track_m: float
    length_m: float
    depth_m: float
    depth_by_side: dict[int, float]
    wheels: tuple[str, ...]
    score: float


@dataclass(frozen=True)
class WheelFlatFinding:
    """A wheel flat: a dip of one wheel's tread, met once per revolution.

    Attributes
    ----------
    wheel : str
    angle_deg : float
        Where on the circumference: the wheel angle ``theta = 2 s / d`` (the
        out-of-roundness phase convention, ``s`` from the run start) of its
        centre, degrees in [0, 360).
    angle_spread_deg : float
        Circular spread of the hits' angles, degrees (small: the hits agree).
    depth_m, length_m : float
        Estimated depth and length (medians over the hits), m.
    n_hits : int
        Dips chained one circumference apart.
    n_revolutions : int
        Revolutions between the first and the last hit.
    first_track_m, last_track_m : float
        Track positions of the first and last hit, m.
    """

    wheel: str
    angle_deg: float
    angle_spread_deg: float
    depth_m: float
    length_m: float
    n_hits: int
    n_revolutions: int
    first_track_m: float
    last_track_m: float


def _chained(s: np.ndarray, circumference: float, tol: float) -> np.ndarray:
    """Dips with another dip one or two circumferences before or after them."""
    order = np.argsort(s)
    ss = s[order]
    hit = np.zeros(ss.size, dtype=bool)
    for k in (1, 2):
        for sign in (1.0, -1.0):
            target = ss + sign * k * circumference
            j = np.clip(np.searchsorted(ss, target), 1, max(ss.size - 1, 1))
            near = np.minimum(np.abs(ss[j - 1] - target), np.abs(ss[np.minimum(j, ss.size - 1)] - target))
            hit |= near <= tol
    out = np.zeros(s.size, dtype=bool)
    out[order] = hit
    return out


def wheel_flats(
    dips: Mapping[str, WheelDips],
    diameters_m: Mapping[str, float],
    *,
    min_hits: int = FLAT_MIN_HITS,
    tol_m: float = FLAT_TOL_M,
) -> tuple[dict[str, WheelFlatFinding], dict[str, np.ndarray]]:
    """Wheel flats: per wheel, the dips that repeat every circumference.

    Parameters
    ----------
    dips : mapping of wheel to WheelDips
        Every wheel's dips over the run.
    diameters_m : mapping of wheel to float
        Wheel diameters, m (best the refined ones: the chain needs the
        circumference within ``tol_m`` over two revolutions).
    min_hits : int
        Chained dips that make a flat.
    tol_m : float
        Tolerance on one circumference, m.

    Returns
    -------
    flats : dict of wheel to WheelFlatFinding
        The wheels with a flat.
    used : dict of wheel to bool array
        Per wheel, which dips belong to its flat (not track impacts).
    """
    if min_hits < 2:
        raise ValueError(f"min_hits: must be >= 2, got {min_hits!r}")
    flats: dict[str, WheelFlatFinding] = {}
    used: dict[str, np.ndarray] = {}
    for wheel, d in dips.items():
        used[wheel] = np.zeros(len(d), dtype=bool)
        if wheel not in diameters_m or len(d) < min_hits:
            continue
        diameter = float(diameters_m[wheel])
        if not (math.isfinite(diameter) and diameter > 0):
            raise ValueError(f"diameters_m: wheel {wheel} needs a diameter > 0 m, got {diameter!r}")
        deep = (d.score >= CANDIDATE_THRESHOLD) & (d.depth_m >= MIN_DEPTH_M)
        chain = np.zeros(len(d), dtype=bool)
        chain[deep] = _chained(d.s_m[deep], math.pi * diameter, tol_m)
        if chain.sum() < min_hits:
            continue
        theta = (2.0 * d.s_m[chain] / diameter) % (2 * math.pi)
        z = np.exp(1j * theta).mean()
        angle = math.degrees(float(np.angle(z))) % 360.0
        spread = math.degrees(math.sqrt(max(-2.0 * math.log(max(abs(z), 1e-12)), 0.0)))
        s_sorted = np.sort(d.s_m[chain])
        flats[wheel] = WheelFlatFinding(
            wheel=wheel, angle_deg=angle, angle_spread_deg=spread,
            depth_m=float(np.median(d.depth_m[chain])), length_m=float(np.median(d.length_m[chain])),
            n_hits=int(chain.sum()),
            n_revolutions=int(round((s_sorted[-1] - s_sorted[0]) / (math.pi * diameter))) + 1,
            first_track_m=float(d.track_m[chain][np.argmin(d.s_m[chain])]),
            last_track_m=float(d.track_m[chain][np.argmax(d.s_m[chain])]),
        )
        used[wheel] = chain
    return flats, used


def track_impacts(
    dips: Mapping[str, WheelDips],
    *,
    exclude: Mapping[str, np.ndarray] | None = None,
    wheels_measured: tuple[str, ...] | None = None,
    pair_threshold: float = PAIR_THRESHOLD,
    single_rail_threshold: float = SINGLE_RAIL_THRESHOLD,
) -> list[TrackImpactFinding]:
    """Track impacts: dips met at the same track position by the wheels of both axles.

    Dips of different wheels within :data:`POSITION_TOL_M` (plus half the
    longer dip) of each other form a cluster. Per rail side, the cluster's
    score is the mean of its axles' scores (they meet the same roughness);
    it is a track impact when the two rails' scores sum to
    ``pair_threshold``, or one rail's reaches ``single_rail_threshold``. With
    two axles measured, at least two wheels of different axles must have met
    it (fixed to the track, not a jolt of the vehicle).

    Parameters
    ----------
    dips : mapping of wheel ("11", "12", "41", "42") to WheelDips
    exclude : mapping of wheel to bool array, optional
        Dips that are not candidates (a wheel flat's hits).
    wheels_measured : tuple of str, optional
        The wheels the run measured (default those in ``dips``): with two axles,
        a track impact needs both.
    pair_threshold, single_rail_threshold : float

    Returns
    -------
    list of TrackImpactFinding
        Ascending track position.
    """
    rows: list[tuple[float, float, float, float, str]] = []
    for wheel, d in dips.items():
        if len(wheel) != 2 or wheel[1] not in "12":
            raise ValueError(f"dips: wheel ids are axle + side ('11' … '42'), got {wheel!r}")
        keep = (d.score >= CANDIDATE_THRESHOLD) & (d.depth_m >= MIN_DEPTH_M)
        if exclude is not None and wheel in exclude:
            keep &= ~np.asarray(exclude[wheel], dtype=bool)
        for x, length, depth, score in zip(d.track_m[keep], d.length_m[keep], d.depth_m[keep], d.score[keep],
                                           strict=True):
            rows.append((float(x), float(length), float(depth), float(score), wheel))
    axles_measured = {w[0] for w in (dips if wheels_measured is None else wheels_measured)}
    rows.sort()
    out: list[TrackImpactFinding] = []
    i = 0
    while i < len(rows):
        j = i + 1
        while j < len(rows) and rows[j][0] - rows[j - 1][0] <= POSITION_TOL_M + 0.5 * max(rows[j][1], rows[j - 1][1]):
            j += 1
        cluster = rows[i:j]
        i = j
        best: dict[str, tuple[float, float, float, float]] = {}
        for x, length, depth, score, wheel in cluster:  # a wheel counts once: its best dip here
            if wheel not in best or score > best[wheel][3]:
                best[wheel] = (x, length, depth, score)
        axles = {w[0] for w in best}
        if len(axles_measured) >= 2 and len(axles) < 2:
            continue
        side_score: dict[int, float] = {}
        side_depth: dict[int, float] = {}
        for side in (1, 2):
            mine = [v for w, v in best.items() if int(w[1]) == side]
            if mine:
                side_score[side] = float(np.mean([v[3] for v in mine]))
                side_depth[side] = float(np.mean([v[2] for v in mine]))
        total = sum(side_score.values())
        if not (total >= pair_threshold or max(side_score.values()) >= single_rail_threshold):
            continue
        top = max(best.values(), key=lambda v: v[3])
        out.append(TrackImpactFinding(
            track_m=float(np.mean([v[0] for v in best.values()])), length_m=top[1],
            depth_m=float(np.mean(list(side_depth.values()))), depth_by_side=side_depth,
            wheels=tuple(sorted(best)), score=total,
        ))
    return out


def one_per_dip(impacts: Sequence[TrackImpactFinding], within_m: float = ONE_DIP_M) -> list[TrackImpactFinding]:
    """One track impact per dip: those within ``within_m`` of one with more evidence dropped.

    A wheel passing a dip rings at the coupled wheel–track resonance, and the inversion of the axle-box
    acceleration to a surface uses a generic track (80 MN/m), not the one under the wheel: where they
    differ (FE runs of 120 MN/m track at 50 m/s, ``bench_impacts.py --case fe-welds``) the estimated
    surface carries the dip's ringing as further dips 1.7–1.9 m after or before it, scoring 0.6 of the
    dip itself — within the single wheel's side-lobe ratio
    (:data:`~app.analysis.impacts.dips.SIDE_LOBE_RATIO`, made for a flat's hits, which score alike) —
    and they were reported as rail features of their own. Two real rail features closer than this (a
    weld beside a joint) are reported as the one with more evidence; its mask covers both.

    Parameters
    ----------
    impacts : sequence of TrackImpactFinding
        Of one kind of evidence (their ``score`` on one scale).
    within_m : float
        m (> 0).

    Returns
    -------
    list of TrackImpactFinding
        Ascending track position.
    """
    if not (math.isfinite(within_m) and within_m > 0):
        raise ValueError(f"within_m: must be > 0, got {within_m!r}")
    kept: list[TrackImpactFinding] = []
    for imp in sorted(impacts, key=lambda i: (-i.score, i.track_m)):
        if all(abs(imp.track_m - k.track_m) >= within_m for k in kept):
            kept.append(imp)
    return sorted(kept, key=lambda i: i.track_m)
