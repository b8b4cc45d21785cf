"""The stiffness index: a bin's amplitude against what its class shows at the same speed.

``index = ln(A / A_ref(class, v))`` (natural log; 0 = a typical location of
the class, +0.1 ≈ 10 % more amplitude than typical at that speed = stiffer in
the sense of the paper), with the reference curves of
:mod:`app.analysis.stiffness.reference_curve`. Its standard uncertainty
combines the curve's standard error at ``v`` and the bin's own spread::

    se = sqrt(se_curve(class, v)^2 + s_bin^2)

``s_bin`` is given per bin (e.g. the spread of the rows aggregated into a
segment) or, by default, the curve's ``repeatability`` (pass-to-pass standard
deviation of one 25 cm bin at similar speed). The index is NaN where the
amplitude or speed is missing, the class has no curve, or the speed lies
outside the curve's supported speeds (the matched-speed rule), or the sample
has no class (None: near a change of superstructure).

This is the one function the stiffness index is computed with: the profile answers and
exports (``index=true``), the analytics (``value=index``, the superstructure conditioning) and
the reference curves' diagnostics, all through :mod:`app.analytics.stiffness_index`. The
segment condition store does not keep it: it keeps the condition index ``ln A`` compared at
matched speed (:mod:`app.analysis.condition.index`), because the curves move as runs arrive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis.stiffness.reference_curve import ReferenceSet

__all__ = ["StiffnessIndex", "stiffness_index"]


@dataclass(frozen=True)
class StiffnessIndex:
    """The index of each sample (arrays of the input's shape).

    Attributes
    ----------
    index : numpy.ndarray
        ``ln(A / A_ref)`` (NaN where undefined).
    se : numpy.ndarray
        Its standard uncertainty, ln units.
    reference_amp : numpy.ndarray
        ``A_ref(class, v)``, m/s².
    z : numpy.ndarray
        ``index / spread``: the index in units of the class's location-to-location spread.
    """

    index: np.ndarray
    se: np.ndarray
    reference_amp: np.ndarray
    z: np.ndarray


def stiffness_index(
    amplitude: np.ndarray,
    speed_mps: np.ndarray,
    classes: np.ndarray,
    reference: ReferenceSet,
    *,
    log_spread: np.ndarray | float | None = None,
) -> StiffnessIndex:
    """``ln(A / A_ref(class, v))`` and its uncertainty for arrays of samples.

    Parameters
    ----------
    amplitude : numpy.ndarray
        Sleeper-passage amplitude, m/s² (any shape; <= 0 or NaN gives NaN).
    speed_mps : numpy.ndarray
        Speed, m/s (same shape).
    classes : numpy.ndarray
        Class label per sample (superstructure type, ``""`` = the line / no
        section; None = no class, e.g. near a change of superstructure), same
        shape, or one label for all.
    reference : ReferenceSet
        The reference curves (:func:`~app.analysis.stiffness.reference_curve.fit_reference_set`,
        or the cached ones of the line).
    log_spread : numpy.ndarray or float, optional
        The sample's own standard deviation in ln units (default: the curve's
        bin repeatability).

    Returns
    -------
    StiffnessIndex
    """
    a = np.asarray(amplitude, dtype=np.float64)
    v = np.asarray(speed_mps, dtype=np.float64)
    if a.shape != v.shape:
        raise ValueError("amplitude, speed_mps: must have equal shapes")
    cls = np.asarray(classes, dtype=object)
    if cls.ndim == 0:
        cls = np.full(a.shape, cls.item(), dtype=object)
    if cls.shape != a.shape:
        raise ValueError("classes: must have the shape of amplitude (or be one label)")
    spread_in = None if log_spread is None else np.broadcast_to(np.asarray(log_spread, dtype=np.float64), a.shape)
    log_ref = np.full(a.shape, np.nan)
    se_curve = np.full(a.shape, np.nan)
    s_bin = np.full(a.shape, np.nan)
    spread = np.full(a.shape, np.nan)
    labels = np.array(["\0" if c is None else str(c) for c in cls.ravel().tolist()], dtype=object).reshape(cls.shape)
    for c, curve in reference.curves.items():
        m = labels == c
        if not m.any() or curve.log_speed.size == 0:
            continue
        log_ref[m], se_curve[m] = curve.evaluate(v[m])
        s_bin[m] = curve.repeatability
        spread[m] = curve.spread
    if spread_in is not None:
        s_bin = spread_in
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = np.isfinite(a) & (a > 0) & np.isfinite(log_ref)
        index = np.where(ok, np.log(np.where(ok, a, 1.0)) - log_ref, np.nan)
        se = np.sqrt(np.nan_to_num(se_curve) ** 2 + np.nan_to_num(s_bin) ** 2)
        se = np.where(ok & (np.isfinite(se_curve) | np.isfinite(s_bin)), se, np.nan)
        z = np.where(spread > 0, index / spread, np.nan)
    return StiffnessIndex(index=index, se=se, reference_amp=np.exp(log_ref), z=z)
