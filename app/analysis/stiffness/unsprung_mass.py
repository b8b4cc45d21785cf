"""Unsprung mass from the sleeper-passage force and acceleration amplitudes.

``F = m_u Z`` per bin: the slope of the regression of the force amplitude
(kN) on the acceleration amplitude (m/s²) is ``m_u / 1000`` (kg). A mass
outside a plausible range (default 150–600 kg) suggests a mis-scaled channel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis.stiffness.regression import LinearFit, linear_fit

__all__ = ["MassFit", "PLAUSIBLE_MASS_KG", "fit_unsprung_mass"]

#: Plausible unsprung mass per wheel, kg.
PLAUSIBLE_MASS_KG: tuple[float, float] = (150.0, 600.0)


@dataclass(frozen=True)
class MassFit:
    """Unsprung mass of one wheel.

    Attributes
    ----------
    mass_kg : float
        Slope of force on acceleration, kg.
    mass_ci : tuple of float
        Its confidence interval, kg.
    plausible : bool
        Whether ``mass_kg`` lies in the plausible range.
    fit : LinearFit
        The regression (slope in kN per m/s², intercept in kN).
    """

    mass_kg: float
    mass_ci: tuple[float, float]
    plausible: bool
    fit: LinearFit


def fit_unsprung_mass(
    acceleration: np.ndarray,
    force_kn: np.ndarray,
    *,
    groups: np.ndarray | None = None,
    hac_lag: int = 400,
    plausible_kg: tuple[float, float] = PLAUSIBLE_MASS_KG,
    confidence: float = 0.95,
) -> MassFit:
    """Regress the force amplitude on the acceleration amplitude.

    Parameters
    ----------
    acceleration : numpy.ndarray
        Sleeper-passage acceleration amplitude per bin, m/s².
    force_kn : numpy.ndarray
        Sleeper-passage force amplitude in the same bins, kN.
    groups : numpy.ndarray, optional
        Series label per sample (run).
    hac_lag : int
        Newey–West lag in bins (default 400 = 100 m).
    plausible_kg : (float, float)
        Plausible mass range, kg.
    confidence : float
        Level of the interval.

    Returns
    -------
    MassFit
    """
    lo, hi = plausible_kg
    if not 0 <= lo < hi:
        raise ValueError(f"plausible_kg: need 0 <= low < high, got {plausible_kg!r}")
    fit = linear_fit(acceleration, force_kn, groups=groups, hac_lag=hac_lag, confidence=confidence)
    mass = 1000.0 * fit.slope
    ci = (1000.0 * fit.slope_ci[0], 1000.0 * fit.slope_ci[1])
    return MassFit(mass_kg=mass, mass_ci=ci, plausible=bool(lo <= mass <= hi), fit=fit)
