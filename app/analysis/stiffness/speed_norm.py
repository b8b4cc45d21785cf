"""Speed dependence of the sleeper-passage amplitude and a speed-normalised indicator.

Model per superstructure type: ``ln A = alpha ln(v / v_ref) + mu(x) + e``, where
``mu(x)`` is the (unknown) stiffness of the location. Where locations were
passed at several speeds (several runs), ``alpha`` is estimated *within*
locations (each bin's samples centred on their mean), so stiffness that
happens to vary with the speed along the line does not bias it. With one
pass per location only, the pooled log–log regression is used (method
``"pooled"``). The normalised indicator is ``A (v_ref / v) ** alpha``; bins
slower than a minimum speed are excluded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis._checks import check_positive, paired_1d
from app.analysis.stiffness.regression import LinearFit, linear_fit

__all__ = ["SpeedFit", "fit_speed_exponent", "normalise_amplitude", "PLAUSIBLE_SPEED_EXPONENT"]

#: Speed exponents a track can have. The excitation of the sleeper passage has a fixed
#: displacement and a frequency proportional to the speed, so its acceleration grows about
#: like v**2 (less where the track yields, a little more near a resonance); an estimate
#: outside this range comes from something else that varies with the speed along the runs
#: (stiffer sections passed faster, e.g.), typically in a pooled fit over one pass.
PLAUSIBLE_SPEED_EXPONENT = (0.0, 3.0)

#: Smallest spread of ln(v) (within locations or pooled) for an estimate.
_MIN_LOG_SPEED_STD = 0.02


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
    """

    exponent: float
    exponent_ci: tuple[float, float]
    method: str
    n_samples: int
    amplitude_at_ref: float
    fit: LinearFit

    @property
    def plausible(self) -> bool:
        """The exponent lies in :data:`PLAUSIBLE_SPEED_EXPONENT` (False when NaN)."""
        lo, hi = PLAUSIBLE_SPEED_EXPONENT
        return bool(lo <= self.exponent <= hi)

    @property
    def warning(self) -> str | None:
        """Why the exponent should not be trusted, or None."""
        if not np.isfinite(self.exponent) or self.plausible:
            return None
        lo, hi = PLAUSIBLE_SPEED_EXPONENT
        hint = (" (pooled over locations passed once: stiffness varying with the speed along the "
                "line biases it; runs passing the same bins at other speeds give a within estimate)"
                if self.method == "pooled" else "")
        return f"exponent {self.exponent:.2f} is outside the physical range {lo:g}…{hi:g}{hint}"


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
    min_speed_mps: float = 25.0 / 3.6,
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
                method, fit = "within", linear_fit(xw, yw, hac_lag=hac_lag)
        if method == "none" and x.std() >= _MIN_LOG_SPEED_STD:
            method, fit = "pooled", linear_fit(x, y, hac_lag=hac_lag)
    exponent = fit.slope if method != "none" else float("nan")
    ci = fit.slope_ci if method != "none" else (float("nan"), float("nan"))
    at_ref = float(np.median(np.exp(y - exponent * x))) if method != "none" else float("nan")
    return SpeedFit(float(exponent), (float(ci[0]), float(ci[1])), method, int(x.size), at_ref, fit)


def normalise_amplitude(
    amplitude: np.ndarray,
    speed_mps: np.ndarray,
    exponent: float | np.ndarray,
    *,
    reference_speed_mps: float,
    min_speed_mps: float = 25.0 / 3.6,
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
