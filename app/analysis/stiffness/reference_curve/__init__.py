"""Reference curves: the expected sleeper-passage amplitude against speed, per class.

A class is a superstructure type (or ``""``: the whole line when no sections
are imported, else the bins outside any section). From all passes of a line the
curve ``A_ref(class, v)`` is estimated robustly and non-parametrically in log
speed, with no speed law assumed:

* the 25 cm rows are reduced to **blocks** (default 10 m) per run and wheel
  (median ``ln A``, median speed): :func:`block_samples`;
* the model is additive in logs, ``ln A = g_class(ln v) + m(location) + e``,
  a location being a block of one rail. ``g`` is a robust local regression
  in ``ln v`` on the medians of fine bins of ``ln v`` (``h / 10`` wide; tricube
  kernel of half-width ``h = ln(1 + tol)``,
  bisquare robustness weights: LOWESS, local quadratic so that resonance
  peaks are not flattened) and ``m`` the median over the
  location's passes; the two are estimated by backfitting. Where locations were
  passed at several speeds (method ``"within"``) only those locations inform
  ``g``, so stiffness that happens to vary with speed along the line (slow
  stretches on stiff track) does not bend the curve; with one pass per
  location (method ``"pooled"``) ``g`` is the local median of the class at
  each speed, which such confounding can bias;
* ``g`` is shifted so that the class's median location has index 0:
  ``A_ref(class, v)`` is the amplitude of a typical location of the class
  at speed ``v``;
* the band: a block bootstrap over 200 m groups of locations (resampled with
  replacement, the backfit repeated) gives the standard error of ``g`` at each
  node and the ``confidence`` band;
* the **matched-speed rule**: ``A_ref(class, v)`` exists only where at least
  ``min_support`` block passes lie within ``±tol`` of ``v`` (in ``ln v``) and
  one within ``±tol/2``; elsewhere the curve is NaN and no index is given: a
  pass is only compared with passes at similar speed.

:func:`bin_repeatability` estimates how much one 25 cm bin's ``ln A`` differs
between two passes at similar speed (pairs of passes of the same rail and bin),
the bin's own share of the index's uncertainty; :func:`wheel_offsets` the
systematic level of each wheel against the others on its rail and the
right/left rail difference (sensor gain or rail).

The package: :mod:`~.smoother` (the robust local regression), :mod:`~.curves` (block passes and
one class's curve), :mod:`~.repeatability` (bin repeatability, wheel offsets), :mod:`~.sets` (a
line's curves, one per class).
"""

from app.analysis.stiffness.reference_curve.curves import (
    BLOCK_M,
    BlockSamples,
    ReferenceCurve,
    block_samples,
    fit_reference_curve,
)
from app.analysis.stiffness.reference_curve.repeatability import (
    WheelOffset,
    bin_repeatability,
    wheel_offsets,
)
from app.analysis.stiffness.reference_curve.sets import (
    ReferenceSet,
    fit_reference_from_rows,
    fit_reference_set,
)

__all__ = [
    "BLOCK_M",
    "BlockSamples",
    "ReferenceCurve",
    "ReferenceSet",
    "WheelOffset",
    "block_samples",
    "bin_repeatability",
    "fit_reference_curve",
    "fit_reference_from_rows",
    "fit_reference_set",
    "wheel_offsets",
]
