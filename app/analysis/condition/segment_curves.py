"""Reference curves from the condition store's 10 m segment rows.

The speed-conditioned index of the places (:mod:`app.analysis.condition.run_places`)
needs ``A_ref(class, v)`` of the line. :mod:`app.analysis.stiffness.reference_curve`
fits it from 25 cm profile rows, which it first reduces to 10 m blocks per run
and wheel (median ``ln A`` and speed); the store's segment rows are such
blocks already — per run, wheel and 10 m segment ``ln A`` and the mean speed,
on the *aligned* km axis — and they are kept for ever (the 25 cm rows may be
swept, a generated fleet has none). :func:`fit_segment_curves` therefore fits
the same curves (:func:`~app.analysis.stiffness.reference_curve.fit_reference_set`:
per class a robust local fit in ``ln v`` with location effects, the
matched-speed rule) to segment rows, a location being a segment of one rail.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE
from app.analysis.stiffness.reference_curve import BlockSamples, ReferenceCurve, fit_reference_curve

__all__ = ["DEFAULT_MIN_LOCATIONS", "segment_samples", "fit_segment_curves"]

#: Distinct locations (10 m of one rail) a speed needs for the curve there: 400 m of track, both rails
#: (measured: ``bench/bench_places.py``; 40 left false places at the braking end of a uniform line).
DEFAULT_MIN_LOCATIONS = 80


def segment_samples(seg: np.ndarray, log_amp: np.ndarray, speed_mps: np.ndarray, run: np.ndarray,
                    wheel: np.ndarray, classes: np.ndarray) -> BlockSamples:
    """Segment rows as block passes.

    Parameters
    ----------
    seg : numpy.ndarray
        Segment number of each row (int).
    log_amp : numpy.ndarray
        ``ln(A / 1 m/s²)`` of each row.
    speed_mps : numpy.ndarray
        Mean speed, m/s.
    run : numpy.ndarray
        Run id of each row.
    wheel : numpy.ndarray
        Wheel label of each row (its last character is the rail side).
    classes : numpy.ndarray
        Class of each row (None: none, the row is left out).

    Returns
    -------
    BlockSamples
        Rows with a finite ``ln A``, a positive speed and a class.
    """
    s = np.asarray(seg)
    arrays = [np.asarray(a) for a in (log_amp, speed_mps, run, wheel, classes)]
    if s.ndim != 1 or any(a.shape != s.shape for a in arrays):
        raise ValueError("seg, log_amp, speed_mps, run, wheel, classes: must be 1-D of equal length")
    la = arrays[0].astype(np.float64)
    v = arrays[1].astype(np.float64)
    cls = arrays[4].astype(object)
    ok = np.isfinite(la) & np.isfinite(v) & (v > 0) & np.array([c is not None for c in cls.tolist()], dtype=bool)
    wheel_s = arrays[3].astype(str)[ok].astype(object)
    rail = np.array([w[-1:] for w in wheel_s.tolist()], dtype=object)
    block = s[ok].astype(np.int64)
    if block.size:
        rail_code = np.unique(rail.astype(str), return_inverse=True)[1].ravel()
        _, location = np.unique(rail_code * (int(block.max() - block.min()) + 1) + (block - block.min()),
                                return_inverse=True)
        location = location.ravel().astype(np.int64)
    else:
        location = np.zeros(0, np.int64)
    return BlockSamples(log_amp=la[ok], log_speed=np.log(v[ok]), location=location, run=arrays[2][ok],
                        wheel=wheel_s, cls=np.array([str(c) for c in cls[ok].tolist()], dtype=object),
                        block=block, rail=rail)


def fit_segment_curves(seg: np.ndarray, log_amp: np.ndarray, speed_mps: np.ndarray, run: np.ndarray,
                       wheel: np.ndarray, classes: np.ndarray, *, speed_tolerance: float = DEFAULT_SPEED_TOLERANCE,
                       min_support: int = 20, min_locations: int = DEFAULT_MIN_LOCATIONS,
                       ) -> dict[str, ReferenceCurve]:
    """The line's reference curve per class from segment rows (arguments as :func:`segment_samples`).

    ``speed_tolerance`` and ``min_support`` as
    :func:`~app.analysis.stiffness.reference_curve.fit_reference_curve`; no bootstrap band and no
    wheel diagnostics (the places need the curve only).

    ``min_locations``: the curve is left out (NaN) at speeds where fewer distinct locations (segments
    of one rail) were passed within the matched-speed window. Where every train brakes at the same
    place, the speeds of a class's low end come from a few hundred metres of track, and a speed law
    fitted there cannot be told from those locations' own stiffness: no index (no anomaly test)
    there rather than a wrong one; the step and trend tests, which compare a segment with itself,
    still watch it.
    """
    if int(min_locations) != min_locations or min_locations < 0:
        raise ValueError(f"min_locations: must be an integer >= 0, got {min_locations!r}")
    samples = segment_samples(seg, log_amp, speed_mps, run, wheel, classes)
    out = {}
    for c in sorted(set(samples.cls.tolist())):
        part = samples.take(samples.cls == c)
        curve = fit_reference_curve(part, c, speed_tolerance=speed_tolerance, min_support=min_support, n_boot=0)
        if min_locations > 0 and curve.log_speed.size:
            n_loc = _locations_per_node(part, curve.log_speed, math.log1p(speed_tolerance))
            curve = replace(curve, log_amp=np.where(n_loc >= min_locations, curve.log_amp, np.nan))
        out[c] = curve
    return out


def _locations_per_node(samples: BlockSamples, nodes: np.ndarray, h: float) -> np.ndarray:
    """Distinct locations with a pass within ``±h`` (ln v) of each node."""
    order = np.argsort(samples.log_speed, kind="stable")
    u, loc = samples.log_speed[order], samples.location[order]
    lo = np.searchsorted(u, nodes - h, side="left")
    hi = np.searchsorted(u, nodes + h, side="right")
    return np.array([np.unique(loc[a:b]).size for a, b in zip(lo, hi, strict=True)], dtype=np.int64)
