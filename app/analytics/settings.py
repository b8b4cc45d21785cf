"""The analytics' settings group (``TRACKVKF_ANALYTICS_*``): which bins the analytics and the condition
store read and how runs are compared. The defaults are the numerics' own constants."""

from __future__ import annotations

from pydantic import Field

from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE
from app.analysis.units import MIN_SPEED_KMH
from app.core.config import SettingsGroup

__all__ = ["AnalyticsSettings", "EDGE_TRIM_M", "SECTION_MARGIN_M", "REFERENCE_SPEED_KMH"]

#: Metres at each end of a run's profile left out (the filters' end transients), m.
EDGE_TRIM_M = 50.0
#: Bins this close to a change of superstructure type get no stiffness index, m.
SECTION_MARGIN_M = 50.0
#: Reference speed of the speed-normalised indicator, km/h.
REFERENCE_SPEED_KMH = 100.0


class AnalyticsSettings(SettingsGroup):
    """Analytics: valid bins, the reference speed and the matched-speed rule.

    Attributes
    ----------
    analytics_min_speed_kmh : float
        Profile bins slower than this (km/h) are left out of the analytics.
    analytics_reference_speed_kmh : float
        Default reference speed of the speed-normalised indicator, km/h.
    analytics_edge_trim_m : float
        The first and last metres of every run's profile left out of the
        analytics (filter end transients).
    analytics_speed_tolerance : float
        The matched-speed rule, wherever runs are compared: two passes are at
        matched speed when ``|ln(v / v0)| <= ln(1 + tol)`` (within a factor
        1 + tol either way; 0.1 = ±10 %; :mod:`app.analysis.speed_match`). The
        reference amplitude at speed v is estimated from such passes and exists
        only where they are; two runs' segments are compared, and a condition
        change is tested against earlier runs, only at matched speed.
    analytics_section_margin_m : float
        Bins within this distance of a change of superstructure type get no
        stiffness index and do not enter the reference curves, m.
    """

    analytics_min_speed_kmh: float = Field(default=MIN_SPEED_KMH, ge=0)
    analytics_reference_speed_kmh: float = Field(default=REFERENCE_SPEED_KMH, gt=0)
    analytics_edge_trim_m: float = Field(default=EDGE_TRIM_M, ge=0)
    analytics_speed_tolerance: float = Field(default=DEFAULT_SPEED_TOLERANCE, gt=0, le=1)
    analytics_section_margin_m: float = Field(default=SECTION_MARGIN_M, ge=0)
