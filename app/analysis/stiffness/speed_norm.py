"""Speed dependence of the sleeper-passage amplitude and a speed-normalised indicator.

Model per superstructure type: ``ln A = alpha ln(v / v_ref) + mu(x) + e``, where
``mu(x)`` is the (unknown) stiffness of the location. Where locations were
passed at several speeds (several runs), ``alpha`` is estimated *within*
locations (each bin's samples centred on their mean), so stiffness that
happens to vary with the speed along the line does not bias it. With one
pass per location only, the pooled log–log regression is used (method
``"pooled"``). The normalised indicator is ``A (v_ref / v) ** alpha``; bins
slower than a minimum speed are excluded.

The power law is an explicit option only (the default speed conditioning is
the stiffness index of :mod:`app.analysis.stiffness.stiffness_index`): the
sleeper-passage amplitude is a wheel–track resonance swept by the sleeper
frequency, not a power law in speed. Every fit is therefore assessed
(:attr:`SpeedFit.stable`, :attr:`SpeedFit.unstable_reasons`); it is unstable
when

* ``"interval_wide"``: its confidence interval is wider than
  :data:`MAX_EXPONENT_CI_WIDTH` (0.5);
* ``"outside_physical_range"``: the exponent lies outside
  :data:`PHYSICAL_EXPONENT_RANGE` (0 … 3: a fixed equivalent roughness gives
  2 below the resonance; one exponent over a wide speed range beyond 3 or
  below 0 is the resonance or confounding speaking);
* ``"speed_spread_small"``: the speeds it rests on vary too little (standard
  deviation of ``ln v``, within locations for ``"within"``, below
  :data:`MIN_STABLE_LOG_SPEED_STD` = 0.1, about ±10 %);
* ``"pooled_confounded"``: one pass per location (method ``"pooled"``): speed
  and local stiffness are confounded along the line;
* ``"not_estimable"``: no estimate (method ``"none"``);
* ``"not_power_law"``: the line's non-parametric reference curve departs from
  the fitted power law by more than :data:`MAX_POWER_LAW_MISFIT` (0.15 in
  ``ln A``) over its speeds (:func:`power_law_misfit`; checked where the
  curve is at hand).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import check_positive, paired_1d
from app.analysis.stiffness.regression import LinearFit, linear_fit
from app.analysis.units import KMH_PER_MPS, MIN_SPEED_KMH

__all__ = [
    "METHODS",
    "SpeedFit",
    "fit_speed_exponent",
    "normalise_amplitude",
    "power_law_misfit",
    "PHYSICAL_EXPONENT_RANGE",
    "MAX_EXPONENT_CI_WIDTH",
    "MIN_STABLE_LOG_SPEED_STD",
    "MAX_POWER_LAW_MISFIT",
]

#: Smallest spread of ln(v) (within locations or pooled) for an estimate.
_MIN_LOG_SPEED_STD = 0.02
#: How an exponent was fitted (``SpeedFit.method``): within locations passed at several speeds,
#: pooled over all locations, or not at all.
METHODS: tuple[str, ...] = ("within", "pooled", "none")
#: Exponents outside this range are flagged unstable.
PHYSICAL_EXPONENT_RANGE: tuple[float, float] = (0.0, 3.0)
#: Confidence intervals wider than this are flagged unstable.
MAX_EXPONENT_CI_WIDTH = 0.5
#: Standard deviation of ln(v) below which the speeds are too alike for a stable exponent.
MIN_STABLE_LOG_SPEED_STD = 0.1
#: Largest departure (ln A) of the reference curve from the fitted power law.
MAX_POWER_LAW_MISFIT = 0.15


@dataclass(frozen=True)
class SpeedFit:
    """Speed exponent of one superstructure type.

    Attributes
    ----------
    exponent : float
        ``alpha`` (NaN when the speeds do not vary enough).
    exponent_ci : tuple of float
        Its confidence interval.
    method : str
        ``"within"`` (locations passed at several speeds), ``"pooled"`` or ``"none"``.
    n_samples : int
        Samples used.
    amplitude_at_ref : float
        Median amplitude normalised to the reference speed, m/s².
    fit : LinearFit
        The underlying regression of ln A on ln(v / v_ref).
    log_speed_std : float
        Standard deviation of the ``ln v`` the exponent rests on (within locations for ``"within"``).
    unstable_reasons : tuple of str
        Why the exponent should not be trusted (module docstring); empty if stable.
    """

    exponent: float
    exponent_ci: tuple[float, float]
    method: str
    n_samples: int
    amplitude_at_ref: float
    fit: LinearFit
    log_speed_std: float = float("nan")
    unstable_reasons: tuple[str, ...] = ()

    @property
    def stable(self) -> bool:
        """No reason to distrust the exponent."""
        return not self.unstable_reasons

    def with_reason(self, reason: str) -> SpeedFit:
        """A copy with one more reason of instability."""
        if reason in self.unstable_reasons:
            return self
        return SpeedFit(self.exponent, self.exponent_ci, self.method, self.n_samples, self.amplitude_at_ref,
                        self.fit, self.log_speed_std, (*self.unstable_reasons, reason))

    @property
    def plausible(self) -> bool:
        """The exponent lies in :data:`PHYSICAL_EXPONENT_RANGE` (False when NaN)."""
        lo, hi = PHYSICAL_EXPONENT_RANGE
        return bool(lo <= self.exponent <= hi)

    @property
    def warning(self) -> str | None:
        """The :attr:`unstable_reasons` in words (None when stable)."""
        if self.stable:
            return None
        lo, hi = PHYSICAL_EXPONENT_RANGE
        width = self.exponent_ci[1] - self.exponent_ci[0]
        text = {
            "not_estimable": "no exponent: the speeds do not vary enough",
            "interval_wide": f"confidence interval {width:.2f} wide (more than {MAX_EXPONENT_CI_WIDTH:g})",
            "outside_physical_range": f"exponent {self.exponent:.2f} is outside the physical range {lo:g}…{hi:g}",
            "speed_spread_small": f"the speeds vary too little (std of ln v {self.log_speed_std:.3f} < "
                                  f"{MIN_STABLE_LOG_SPEED_STD:g})",
            "pooled_confounded": "pooled over locations passed once: stiffness varying with the speed along "
                                 "the line biases it; runs passing the same bins at other speeds give a within "
                                 "estimate",
            "not_power_law": f"the line's reference curve departs from a power law by more than "
                             f"{MAX_POWER_LAW_MISFIT:g} in ln A",
        }
        return "; ".join(text.get(r, r) for r in self.unstable_reasons)


def _reasons(method: str, exponent: float, ci: tuple[float, float], log_speed_std: float) -> tuple[str, ...]:
    if method == "none":
        return ("not_estimable",)
    out = []
    if not ci[1] - ci[0] <= MAX_EXPONENT_CI_WIDTH:
        out.append("interval_wide")
    lo, hi = PHYSICAL_EXPONENT_RANGE
    if not lo <= exponent <= hi:
        out.append("outside_physical_range")
    if not log_speed_std >= MIN_STABLE_LOG_SPEED_STD:
        out.append("speed_spread_small")
    if method == "pooled":
        out.append("pooled_confounded")
    return tuple(out)

def _check(amplitude, speed_mps, reference_speed_mps, min_speed_mps):
    a, v = paired_1d(amplitude, speed_mps, "amplitude, speed_mps")
    check_positive(reference_speed_mps, "reference_speed_mps")
    if not min_speed_mps >= 0:
        raise ValueError(f"min_speed_mps: must be >= 0, got {min_speed_mps!r}")
    return a, v


def fit_speed_exponent(
    amplitude: np.ndarray,
    speed_mps: np.ndarray,
    location: np.ndarray,
    *,
    reference_speed_mps: float,
    min_speed_mps: float = MIN_SPEED_KMH / KMH_PER_MPS,
    hac_lag: int = 400,
) -> SpeedFit:
    """Fit ``alpha`` of ``A ∝ v ** alpha``.

    Parameters
    ----------
    amplitude : numpy.ndarray
        Sleeper-passage amplitude per sample (run × bin), m/s².
    speed_mps : numpy.ndarray
        Speed of each sample, m/s.
    location : numpy.ndarray
        Bin index of each sample (samples of the same location are compared).
    reference_speed_mps : float
        ``v_ref``, m/s.
    min_speed_mps : float
        Samples slower than this are excluded, m/s (default 25 km/h).
    hac_lag : int
        Newey–West lag in samples (in location order) for the interval.
    """
    a, v = _check(amplitude, speed_mps, reference_speed_mps, min_speed_mps)
    loc = np.asarray(location)
    if loc.shape != a.shape:
        raise ValueError("location: must have the shape of amplitude")
    ok = np.isfinite(a) & (a > 0) & np.isfinite(v) & (v >= max(min_speed_mps, 1e-9))
    a, v, loc = a[ok], v[ok], loc[ok]
    x, y = np.log(v / reference_speed_mps), np.log(a)
    method, fit = "none", linear_fit(np.zeros(0), np.zeros(0))
    spread = float("nan")
    if x.size >= 3:
        order = np.argsort(loc, kind="stable")
        x, y, loc = x[order], y[order], loc[order]
        uniq, inv, counts = np.unique(loc, return_inverse=True, return_counts=True)
        multi = counts[inv] >= 2
        if multi.sum() >= 3:
            xm = np.bincount(inv, weights=x) / counts
            ym = np.bincount(inv, weights=y) / counts
            xw, yw = (x - xm[inv])[multi], (y - ym[inv])[multi]
            if xw.std() >= _MIN_LOG_SPEED_STD:
                method, fit, spread = "within", linear_fit(xw, yw, hac_lag=hac_lag), float(xw.std())
        if method == "none" and x.std() >= _MIN_LOG_SPEED_STD:
            method, fit, spread = "pooled", linear_fit(x, y, hac_lag=hac_lag), float(x.std())
    exponent = fit.slope if method != "none" else float("nan")
    ci = fit.slope_ci if method != "none" else (float("nan"), float("nan"))
    at_ref = float(np.median(np.exp(y - exponent * x))) if method != "none" else float("nan")
    ci = (float(ci[0]), float(ci[1]))
    return SpeedFit(float(exponent), ci, method, int(x.size), at_ref, fit, spread,
                    _reasons(method, float(exponent), ci, spread))


def power_law_misfit(log_speed: np.ndarray, log_amp: np.ndarray, exponent: float) -> float:
    """Largest departure (ln units) of a curve ``ln A(ln v)`` from ``exponent · ln v + c`` (best c).

    ``c`` is the median offset; NaN nodes are ignored (NaN if none is left or
    the exponent is NaN). Compare with :data:`MAX_POWER_LAW_MISFIT`.
    """
    u = np.asarray(log_speed, dtype=np.float64)
    y = np.asarray(log_amp, dtype=np.float64)
    if u.shape != y.shape:
        raise ValueError("log_speed, log_amp: must have equal shapes")
    ok = np.isfinite(u) & np.isfinite(y)
    if not ok.any() or not np.isfinite(exponent):
        return float("nan")
    r = y[ok] - exponent * u[ok]
    return float(np.max(np.abs(r - np.median(r))))


def normalise_amplitude(
    amplitude: np.ndarray,
    speed_mps: np.ndarray,
    exponent: float | np.ndarray,
    *,
    reference_speed_mps: float,
    min_speed_mps: float = MIN_SPEED_KMH / KMH_PER_MPS,
) -> np.ndarray:
    """Amplitude at the reference speed, ``A (v_ref / v) ** alpha`` (m/s²).

    NaN where the speed is below ``min_speed_mps``, the amplitude is missing or
    the exponent is NaN.

    Parameters
    ----------
    amplitude : numpy.ndarray
        Amplitude per bin, m/s².
    speed_mps : numpy.ndarray
        Speed per bin, m/s.
    exponent : float or numpy.ndarray
        ``alpha`` (scalar or per bin, e.g. per superstructure type).
    reference_speed_mps, min_speed_mps : float
        ``v_ref`` and the minimum speed, m/s.
    """
    a, v = _check(amplitude, speed_mps, reference_speed_mps, min_speed_mps)
    alpha = np.broadcast_to(np.asarray(exponent, dtype=np.float64), a.shape)
    out = np.full(a.shape, np.nan)
    ok = np.isfinite(a) & np.isfinite(v) & (v >= max(min_speed_mps, 1e-9)) & np.isfinite(alpha)
    out[ok] = a[ok] * (reference_speed_mps / v[ok]) ** alpha[ok]
    return out
