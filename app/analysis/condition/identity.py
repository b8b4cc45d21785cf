"""Identity of places across runs: today's places matched to the known ones on the aligned km axis.

A place keeps one id while the runs keep finding it. After the store aligned a
run to its line (odometry drift taken out), today's place ``i`` continues the
known place ``j`` when

* both go in the same **direction** (a soft place does not continue a hard one), and
* their extents, each widened by ``tolerance_m`` at both ends, **overlap**
  (alignment residuals and a place whose extent grows by a segment still match).

Among the candidate pairs the match is one-to-one, greedy by the largest
overlap of the widened extents (then the nearest centres): when a place splits,
its larger part keeps the id and the other becomes a new place; when two known
places merge, the one overlapping more continues and the other is not confirmed
by this run.

:func:`tendency` reads a place's severity trend as growing / stable / shrinking;
:func:`covering_actions` finds the maintenance actions over a place.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis.condition.outlook import Trend

__all__ = ["PlaceMatch", "match_places", "TENDENCIES", "tendency", "covering_actions"]

#: Readings of a place's trend.
TENDENCIES = ("new", "growing", "stable", "shrinking")


@dataclass(frozen=True)
class PlaceMatch:
    """Today's places against the known ones.

    Attributes
    ----------
    known : numpy.ndarray
        int64 per today's place: the index of the known place it continues, −1 for a new place.
    overlap_m : numpy.ndarray
        Overlap of the widened extents of each matched pair, m (0 for new places).
    unconfirmed : numpy.ndarray
        int64 indices of known places no place of today continues.
    """

    known: np.ndarray
    overlap_m: np.ndarray
    unconfirmed: np.ndarray


def _extents(start: object, end: object, direction: object, names: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a = np.asarray(start, dtype=np.float64)
    b = np.asarray(end, dtype=np.float64)
    d = np.asarray(direction)
    if not (a.ndim == 1 and b.shape == a.shape and d.shape == a.shape):
        raise ValueError(f"{names}: must be 1-D of equal length")
    if a.size and not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(b >= a)):
        raise ValueError(f"{names}: extents must be finite with start <= end")
    return a, b, d.astype(np.int64)


def match_places(
    new_start: np.ndarray, new_end: np.ndarray, new_direction: np.ndarray,
    known_start: np.ndarray, known_end: np.ndarray, known_direction: np.ndarray,
    *, tolerance_m: float = 10.0,
) -> PlaceMatch:
    """Match today's places to the known ones (module docstring).

    Parameters
    ----------
    new_start, new_end, new_direction : numpy.ndarray
        Today's places: extent on the aligned km axis (m) and direction (±1).
    known_start, known_end, known_direction : numpy.ndarray
        The known places (their latest extent).
    tolerance_m : float
        Widening of each extent at both ends, m (≥ 0).

    Returns
    -------
    PlaceMatch
    """
    if not (np.isfinite(tolerance_m) and tolerance_m >= 0):
        raise ValueError(f"tolerance_m: must be a finite number >= 0, got {tolerance_m!r}")
    na, nb, nd = _extents(new_start, new_end, new_direction, "new_start, new_end, new_direction")
    ka, kb, kd = _extents(known_start, known_end, known_direction, "known_start, known_end, known_direction")
    known = np.full(na.size, -1, np.int64)
    overlap = np.zeros(na.size)
    if na.size and ka.size:
        order = np.argsort(ka, kind="stable")
        ka_s = ka[order]
        longest = float(np.max(kb - ka))
        pairs: list[tuple[float, float, int, int]] = []
        for i in range(na.size):
            lo = np.searchsorted(ka_s, na[i] - 2 * tolerance_m - longest, side="left")
            hi = np.searchsorted(ka_s, nb[i] + 2 * tolerance_m, side="right")
            for jj in range(lo, hi):
                j = int(order[jj])
                if kd[j] != nd[i]:
                    continue
                ov = min(nb[i], kb[j]) - max(na[i], ka[j]) + 2 * tolerance_m
                if ov > 0 or (ov == 0 and tolerance_m == 0 and max(na[i], ka[j]) <= min(nb[i], kb[j])):
                    dist = abs(0.5 * (na[i] + nb[i]) - 0.5 * (ka[j] + kb[j]))
                    pairs.append((-ov, dist, i, j))
        pairs.sort()
        taken = np.zeros(ka.size, bool)
        for neg_ov, _, i, j in pairs:
            if known[i] < 0 and not taken[j]:
                known[i] = j
                overlap[i] = -neg_ov
                taken[j] = True
        unconfirmed = np.flatnonzero(~taken).astype(np.int64)
    else:
        unconfirmed = np.arange(ka.size, dtype=np.int64)
    return PlaceMatch(known=known, overlap_m=overlap, unconfirmed=unconfirmed)


def tendency(trend: Trend, *, min_runs: int = 3) -> str:
    """``"new"`` (fewer than ``min_runs`` runs), else ``"growing"`` / ``"shrinking"`` where the severity's
    trend is significant upwards / downwards, and ``"stable"`` otherwise."""
    if trend.n < min_runs:
        return "new"
    if trend.significant and trend.rate_per_year > 0:
        return "growing"
    if trend.significant and trend.rate_per_year < 0:
        return "shrinking"
    return "stable"


def covering_actions(place_start: float, place_end: float, action_start: np.ndarray, action_end: np.ndarray,
                     *, min_cover: float = 0.5) -> np.ndarray:
    """Indices of the maintenance actions that cover at least ``min_cover`` of a place's extent.

    Parameters
    ----------
    place_start, place_end : float
        The place's extent, m.
    action_start, action_end : numpy.ndarray
        The actions' extents, m.
    min_cover : float
        Fraction of the place an action must cover, in (0, 1].

    Returns
    -------
    numpy.ndarray
        int64 indices, in input order.
    """
    if not 0 < min_cover <= 1:
        raise ValueError(f"min_cover: must be in (0, 1], got {min_cover!r}")
    if not (np.isfinite(place_start) and np.isfinite(place_end) and place_end >= place_start):
        raise ValueError("place_start, place_end: must be finite with start <= end")
    a = np.asarray(action_start, dtype=np.float64)
    b = np.asarray(action_end, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError("action_start, action_end: must be 1-D of equal length")
    length = place_end - place_start
    cover = np.clip(np.minimum(b, place_end) - np.maximum(a, place_start), 0.0, None)
    if length <= 0:
        hit = (a <= place_start) & (b >= place_end)
    else:
        hit = cover >= min_cover * length - 1e-9
    return np.flatnonzero(hit).astype(np.int64)
