"""Isolated impacts: dipped welds and joints (fixed to the track) and wheel flats (fixed to a wheel).

* :mod:`~app.analysis.impacts.surface` estimates the running surface under a
  wheel from its axle-box acceleration (the wheel–track dynamics inverted);
* :mod:`~app.analysis.impacts.dips` finds isolated dips in it (matched filters
  after whitening) with their length and depth;
* :mod:`~app.analysis.impacts.classify` tells the two kinds apart: a track
  impact is met by every wheel at the same track position, a wheel flat by
  one wheel once per revolution;
* :mod:`~app.analysis.impacts.welds` finds welds on rough rail: the weld
  filters' scores of all wheels combined at one track position (the two
  rails' independent roughness);
* :mod:`~app.analysis.impacts.mask` keeps track impacts out of the sleeper
  indicator (the bins they disturb are bridged).
"""

from app.analysis.impacts.dips import DETECTION_THRESHOLD, DIP_LENGTHS_M, Dips, find_dips
from app.analysis.impacts.surface import SurfaceEstimate, surface_estimate

__all__ = [
    "DETECTION_THRESHOLD",
    "DIP_LENGTHS_M",
    "Dips",
    "find_dips",
    "SurfaceEstimate",
    "surface_estimate",
]
