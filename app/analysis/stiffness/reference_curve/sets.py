"""The reference curves of a line and track: one curve per class
(:func:`~app.analysis.stiffness.reference_curve.curves.fit_reference_curve`) with the bin
repeatability and the wheel diagnostics (:mod:`~app.analysis.stiffness.reference_curve.repeatability`),
from block passes (:func:`fit_reference_set`) or from the 25 cm rows (:func:`fit_reference_from_rows`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE
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

__all__ = ["ReferenceSet", "fit_reference_set", "fit_reference_from_rows"]


@dataclass(frozen=True)
class ReferenceSet:
    """The reference curves of a line and track, one per class, and their diagnostics.

    Attributes
    ----------
    curves : dict[str, ReferenceCurve]
        By class label.
    wheel_offsets : tuple of WheelOffset
        Per wheel (diagnostic; the curves pool all wheels).
    rail_difference : float
        Median over blocks of ``m(rail 2) - m(rail 1)`` (ln units; NaN if not both rails).
    speed_tolerance : float
        ``tol`` of the matched-speed rule.
    block_m : float
        Block length of the fit, m.
    """

    curves: dict[str, ReferenceCurve]
    wheel_offsets: tuple[WheelOffset, ...] = ()
    rail_difference: float = float("nan")
    speed_tolerance: float = DEFAULT_SPEED_TOLERANCE
    block_m: float = BLOCK_M
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form."""
        return {
            "curves": {k: c.to_dict() for k, c in self.curves.items()},
            "wheel_offsets": [{"wheel": o.wheel, "offset": _num(o.offset), "low": _num(o.low),
                               "high": _num(o.high), "n_samples": o.n_samples} for o in self.wheel_offsets],
            "rail_difference": _num(self.rail_difference), "speed_tolerance": self.speed_tolerance,
            "block_m": self.block_m, "extra": dict(self.extra),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ReferenceSet:
        """Inverse of :meth:`to_dict`."""

        def f(x: Any) -> float:
            return float("nan") if x is None else float(x)

        return cls(
            curves={k: ReferenceCurve.from_dict(c) for k, c in d["curves"].items()},
            wheel_offsets=tuple(WheelOffset(str(o["wheel"]), f(o["offset"]), f(o["low"]), f(o["high"]),
                                            int(o["n_samples"])) for o in d.get("wheel_offsets", [])),
            rail_difference=f(d.get("rail_difference")), speed_tolerance=float(d["speed_tolerance"]),
            block_m=float(d.get("block_m", BLOCK_M)), extra=dict(d.get("extra", {})),
        )


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def fit_reference_set(
    samples: BlockSamples,
    *,
    speed_tolerance: float = DEFAULT_SPEED_TOLERANCE,
    min_support: int = 20,
    confidence: float = 0.9,
    n_boot: int = 40,
    repeatability: float = float("nan"),
    seed: int = 0,
) -> ReferenceSet:
    """One curve per class of ``samples`` (:func:`fit_reference_curve`) and the wheel diagnostics."""
    curves = {}
    for c in sorted(set(samples.cls.astype(str))):
        curve = fit_reference_curve(samples.take(samples.cls.astype(str) == c), c, speed_tolerance=speed_tolerance,
                                    min_support=min_support, confidence=confidence, n_boot=n_boot, seed=seed)
        curves[c] = curve.with_repeatability(repeatability)
    offsets, rail_diff = wheel_offsets(samples, curves, confidence=confidence, seed=seed)
    return ReferenceSet(curves, offsets, rail_diff, float(speed_tolerance))


def fit_reference_from_rows(
    amplitude: np.ndarray,
    speed_mps: np.ndarray,
    position_m: np.ndarray,
    run: np.ndarray,
    wheel: np.ndarray,
    rail: np.ndarray,
    cls: np.ndarray,
    *,
    bin_length_m: float = 0.25,
    block_m: float = BLOCK_M,
    speed_tolerance: float = DEFAULT_SPEED_TOLERANCE,
    min_support: int = 20,
    confidence: float = 0.9,
    n_boot: int = 40,
    seed: int = 0,
) -> ReferenceSet:
    """The reference curves of a line from its 25 cm profile rows (all runs and wheels).

    :func:`block_samples`, then :func:`fit_reference_set` with the bin
    repeatability (:func:`bin_repeatability`) of the rows. Arguments as there;
    ``rail`` is the rail side of each row's wheel.
    """
    a = np.asarray(amplitude, dtype=np.float64)
    v = np.asarray(speed_mps, dtype=np.float64)
    samples = block_samples(a, v, position_m, run, wheel, rail, cls, block_m=block_m,
                            bin_length_m=bin_length_m)
    with np.errstate(invalid="ignore", divide="ignore"):
        la, lv = np.log(a), np.log(v)
    run_code = np.unique(np.asarray(run), return_inverse=True)[1].ravel()
    wheel_u, wheel_code = np.unique(np.asarray(wheel).astype(str), return_inverse=True)
    passes = run_code * wheel_u.size + wheel_code.ravel()
    rail_code = np.unique(np.asarray(rail).astype(str), return_inverse=True)[1].ravel()
    rep = bin_repeatability(la, lv, rail_code, np.floor(np.asarray(position_m) / bin_length_m), passes,
                            speed_tolerance=speed_tolerance)
    out = fit_reference_set(samples, speed_tolerance=speed_tolerance, min_support=min_support,
                            confidence=confidence, n_boot=n_boot, repeatability=rep, seed=seed)
    return ReferenceSet(out.curves, out.wheel_offsets, out.rail_difference, out.speed_tolerance, block_m,
                        {"n_rows": int(a.size), "n_blocks": len(samples)})
