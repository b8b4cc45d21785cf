"""The condition index of the segment condition store: the log of the raw amplitude, ``ln(A / 1 m/s²)``.

Two indexes live in trackvkf, with distinct names everywhere:

- the **condition index** (this module, provenance name :data:`LOG_AMPLITUDE_INDEX`,
  ``"ln_amplitude"``): what the segment condition store keeps for every 10 m / 100 m segment
  and what its change tests, heat maps, trends, hotspots and maintenance effects compare. It
  is not speed-conditioned itself: values are compared only at matched speed
  (:mod:`app.analysis.speed_match`; the change tests also level each run against its
  surroundings and estimate a speed exponent within segments,
  :mod:`app.analysis.condition.change`), so rows stored years apart stay comparable;
- the **stiffness index** ``ln(A / A_ref(class, v))`` (:mod:`app.analysis.stiffness.stiffness_index`):
  the amplitude against the line's current reference curves, answered with the profiles
  (``index=true``) and the analytics; it moves when the curves are re-estimated, which is why
  the store does not keep it.

:mod:`app.condition.index` is the one place that decides which index the store holds.
"""

from __future__ import annotations

import numpy as np

__all__ = ["LOG_AMPLITUDE_INDEX", "log_amplitude_index"]

#: Name of the condition index in the provenance of stored rows (``meta["condition"]["index"]``,
#: the heat map's ``index``).
LOG_AMPLITUDE_INDEX = "ln_amplitude"


def log_amplitude_index(amplitude: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``ln(A / 1 m/s²)`` per bin (NaN where ``A`` is not positive) and its uncertainty (0: none known).

    Parameters
    ----------
    amplitude : numpy.ndarray
        Sleeper-passage amplitude, m/s².

    Returns
    -------
    index, index_sd : numpy.ndarray
    """
    a = np.asarray(amplitude, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        index = np.where(a > 0, np.log(np.where(a > 0, a, 1.0)), np.nan)
    return index, np.zeros_like(index)
