"""The matched-speed rule: when two passes of a place count as passed at the same speed.

Two passes at speeds ``v`` and ``v0`` are matched when ``|ln(v / v0)| <= ln(1 + tol)``: within a
factor ``1 + tol`` either way. The rule is symmetric (``v`` matches ``v0`` exactly when ``v0``
matches ``v``; the relative form ``|v / v0 − 1| <= tol`` is not: it admits 0.90·v0 but not
v0 / 0.90), so a pair of runs is matched or not whichever of them is the newer, and it is
the natural measure for an amplitude that follows speed in log–log (the speed-conditioning of
the stiffness index and of the change tests). Every comparison at matched speed uses it: the
change tests of the condition store (:func:`app.analysis.condition.change.speed_matched`), the
reference curves' repeatability (:func:`app.analysis.stiffness.reference_curve.bin_repeatability`)
and the change column of the segment table (:func:`app.analysis.stiffness.alignment.segment_table`),
all with the one setting ``TRACKVKF_ANALYTICS_SPEED_TOLERANCE`` (default
:data:`DEFAULT_SPEED_TOLERANCE`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["DEFAULT_SPEED_TOLERANCE", "log_speed_tolerance", "log_speeds_matched", "speeds_matched"]

#: Default tolerance of the matched-speed rule: within 10 % either way.
DEFAULT_SPEED_TOLERANCE = 0.1


def log_speed_tolerance(tolerance: float) -> float:
    """The largest ``|ln(v / v0)|`` of matched passes, ``ln(1 + tolerance)``.

    Raises
    ------
    ValueError
        If ``tolerance`` is not a finite number > 0.
    """
    if not (isinstance(tolerance, int | float | np.floating) and math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance: must be a finite number > 0, got {tolerance!r}")
    return math.log1p(float(tolerance))


def log_speeds_matched(log_ratio: np.ndarray | float, tolerance: float) -> np.ndarray:
    """Whether passes whose log speed ratio is ``log_ratio`` (``ln(v / v0)``) are matched (NaN: not)."""
    with np.errstate(invalid="ignore"):
        return np.abs(np.asarray(log_ratio, dtype=np.float64)) <= log_speed_tolerance(tolerance)


def speeds_matched(speed: np.ndarray | float, reference_speed: np.ndarray | float, tolerance: float) -> np.ndarray:
    """Whether passes at ``speed`` and ``reference_speed`` (same unit, broadcast) are matched.

    ``|ln(speed / reference_speed)| <= ln(1 + tolerance)``; False where either speed is not a
    positive finite number.
    """
    v = np.asarray(speed, dtype=np.float64)
    v0 = np.asarray(reference_speed, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return log_speeds_matched(np.log(v / v0), tolerance)
