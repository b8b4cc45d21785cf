"""The index over an extent of one run, relative to the track around it: what an action's effect is read from.

A maintenance action's effect (:func:`~app.analysis.condition.maintenance_effect.action_effect`)
compares the index over the action's extent before and after its day. Read
absolutely, that comparison also carries whatever moves the whole run: the
calibration of the day's vehicle and sensors, the fit of the reference curves
at the day's speeds (a run a few per cent faster than the others sits slightly
off the curve everywhere). Those move the track around the extent by the same
amount, so :func:`extent_level` reads the extent against it:

``median(index inside [start, end)) − mean(index within around_m of the extent's centre,
outside the extent widened by margin_m)``

The median inside, because the extent may hold the very place the action was
for (a few segments far from the rest before the action); the mean around,
because the surroundings are typical track whose run-to-run noise averages
out; the margin keeps out the tapers at the extent's ends (the work of a
tamping machine ramps in and out over some metres).

Measured on histories through the real pipeline (``bench/bench_places.py``): a
tamping of −20.0 % reads −18.5 / −19.4 / −20.1 % this way from the speed-conditioned
index, −18.2 / −14.6 / −31.4 % from ``ln A`` over the extent against the mean of the
100 m rows within ±1 km (the maintenance effect's rule before issue 31). The one rule of
an extent against its surroundings: the maintenance effect (``/condition/maintenance-effect``,
:mod:`app.places.effect`) and a segment's trend relative to its surroundings
(``/condition/trend``) read the store's condition index this way, with
``TRACKVKF_PLACES_EFFECT_AROUND_M`` / ``_MARGIN_M``.
"""

from __future__ import annotations

import numpy as np

from app.analysis._checks import check_positive
from app.analysis.speed_match import speeds_matched

__all__ = ["extent_level", "surroundings_level", "like_surroundings", "DEFAULT_AROUND_M", "DEFAULT_MARGIN_M",
           "DEFAULT_MIN_SEGMENTS"]

#: Half-width of the surroundings from the extent's centre, m (``TRACKVKF_PLACES_EFFECT_AROUND_M``).
DEFAULT_AROUND_M = 1000.0
#: Widening of the extent kept out of the surroundings, m (``TRACKVKF_PLACES_EFFECT_MARGIN_M``).
DEFAULT_MARGIN_M = 50.0
#: Segments with a value needed inside and around.
DEFAULT_MIN_SEGMENTS = 3


def _check(seg: np.ndarray, index: np.ndarray, start_m: float, end_m: float, segment_m: float, around_m: float,
           margin_m: float, min_segments: int) -> tuple[np.ndarray, np.ndarray]:
    check_positive(segment_m, "segment_m")
    check_positive(around_m, "around_m")
    if not (np.isfinite(start_m) and np.isfinite(end_m) and start_m < end_m):
        raise ValueError(f"start_m, end_m: must be finite with start_m < end_m, got {start_m!r}, {end_m!r}")
    if not (np.isfinite(margin_m) and margin_m >= 0):
        raise ValueError(f"margin_m: must be a finite number >= 0, got {margin_m!r}")
    if int(min_segments) != min_segments or min_segments < 1:
        raise ValueError(f"min_segments: must be an integer >= 1, got {min_segments!r}")
    s = np.asarray(seg, dtype=np.float64)
    x = np.asarray(index, dtype=np.float64)
    if s.ndim != 1 or x.shape != s.shape:
        raise ValueError("seg, index: must be 1-D of equal length")
    return (s + 0.5) * segment_m, x


def surroundings_level(seg: np.ndarray, index: np.ndarray, start_m: float, end_m: float, *, segment_m: float,
                       around_m: float = DEFAULT_AROUND_M, margin_m: float = DEFAULT_MARGIN_M,
                       min_segments: int = DEFAULT_MIN_SEGMENTS) -> float:
    """The level of the track around ``[start_m, end_m)`` in one run: the mean index of the segments within
    ``around_m`` of the extent's centre, outside the extent widened by ``margin_m`` (module docstring).

    Parameters are those of :func:`extent_level`. Returns ln units; NaN with fewer than ``min_segments``
    values around.
    """
    centres, x = _check(seg, index, start_m, end_m, segment_m, around_m, margin_m, min_segments)
    mid = 0.5 * (start_m + end_m)
    around = np.isfinite(x) & (np.abs(centres - mid) < around_m) \
        & ~((centres >= start_m - margin_m) & (centres < end_m + margin_m))
    if around.sum() < min_segments:
        return float("nan")
    return float(np.mean(x[around]))


def extent_level(seg: np.ndarray, index: np.ndarray, start_m: float, end_m: float, *, segment_m: float,
                 around_m: float = DEFAULT_AROUND_M, margin_m: float = DEFAULT_MARGIN_M, relative: bool = True,
                 min_segments: int = DEFAULT_MIN_SEGMENTS, min_inside: int | None = None) -> float:
    """The index of a run over ``[start_m, end_m)``, relative to the track around it (module docstring).

    Parameters
    ----------
    seg : numpy.ndarray
        Segment numbers (segment ``k`` covers ``[k · segment_m, (k + 1) · segment_m)``).
    index : numpy.ndarray
        Index per segment (mean over the wheels; ln units; NaN: no value).
    start_m, end_m : float
        The extent on the aligned km axis, m (``start_m < end_m``).
    segment_m : float
        Segment length, m (> 0).
    around_m : float
        Half-width of the surroundings, from the extent's centre, m (> 0).
    margin_m : float
        Widening of the extent kept out of the surroundings, m (≥ 0).
    relative : bool
        False: the median inside only (no reference to the surroundings).
    min_segments : int
        Segments with a value needed inside and (when relative) around (≥ 1).
    min_inside : int, optional
        Segments with a value needed inside (≥ 1; default ``min_segments``: an extent of fewer segments
        than that).

    Returns
    -------
    float
        ln units; NaN where either side has fewer values than it needs.
    """
    need = min_segments if min_inside is None else min_inside
    centres, x = _check(seg, index, start_m, end_m, segment_m, around_m, margin_m, min_segments)
    if int(need) != need or need < 1:
        raise ValueError(f"min_inside: must be an integer >= 1, got {min_inside!r}")
    inside = np.isfinite(x) & (centres >= start_m) & (centres < end_m)
    if inside.sum() < need:
        return float("nan")
    level = float(np.median(x[inside]))
    if not relative:
        return level
    return level - surroundings_level(seg, index, start_m, end_m, segment_m=segment_m, around_m=around_m,
                                      margin_m=margin_m, min_segments=min_segments)


def like_surroundings(inside: np.ndarray, classes: np.ndarray | None, speed: np.ndarray | None,
                      tolerance: float) -> list[np.ndarray]:
    """The segments an extent may be read against, most alike first (issue 33, the maintenance effect): those
    of the extent's own superstructure class passed at its speed, then any classified segment at its speed
    (where the extent is nearly its whole class section). A ramp or a section of another class moves with the
    speed differently from the extent, so a speed mix would read as a change.

    Parameters
    ----------
    inside : numpy.ndarray
        (segments,) bool, the extent's segments.
    classes : numpy.ndarray or None
        (segments,) class of each segment (None entries: at a change of class); None (or no class): any.
    speed : numpy.ndarray or None
        (segments,) speed of the run over each segment (m/s, NaN: none); None: any speed.
    tolerance : float
        Of the matched-speed rule (> 0).

    Returns
    -------
    list of numpy.ndarray
        Masks of the segments (bool, the extent's own included) to try in turn.
    """
    inside = np.asarray(inside, dtype=bool)
    matched = np.ones(inside.shape, dtype=bool)
    if speed is not None:
        v = np.asarray(speed, dtype=np.float64)
        own = v[inside & np.isfinite(v)]
        matched = speeds_matched(v, float(np.median(own)), tolerance) if own.size else np.zeros(inside.shape, bool)
    cls = list(classes) if classes is not None else []
    typed = np.array([c is not None for c in cls], dtype=bool)
    if not typed.any():  # no classes known
        return [inside | matched]
    mine = [c for c, k in zip(cls, inside.tolist(), strict=True) if k and c is not None]
    out = []
    if mine:
        top = max(set(mine), key=mine.count)
        out.append(inside | (np.array([c == top for c in cls], dtype=bool) & matched))
    out.append(inside | (typed & matched))
    return out
