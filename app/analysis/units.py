"""The unit conversions and the speed floor every layer above the numerics shares, named once.

The API answers speeds in km/h (``speed_kmh``, ``*_kmh``); the numerics and the stored rows work in
m/s (``speed_mean``, ``*_mps``): one factor converts between them, :data:`KMH_PER_MPS`. Rates per
year divide days by :data:`DAYS_PER_YEAR`. :data:`MIN_SPEED_KMH` is the slowest speed an indicator
is taken at (``TRACKVKF_MIN_SPEED_KMH`` of the processing, ``TRACKVKF_ANALYTICS_MIN_SPEED_KMH`` of the
analyses and the condition store).
"""

from __future__ import annotations

__all__ = ["KMH_PER_MPS", "DAYS_PER_YEAR", "MIN_SPEED_KMH"]

#: km/h in one m/s (3600 s/h ÷ 1000 m/km).
KMH_PER_MPS = 3.6
#: Days of a mean (Julian) year, for rates per year.
DAYS_PER_YEAR = 365.25
#: Slowest speed used for indicators, km/h: slower bins are no valid measurement.
MIN_SPEED_KMH = 25.0
