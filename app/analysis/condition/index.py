"""The provisional condition index of 25 cm bins: the log of the raw amplitude.

Until the speed-conditioned stiffness index (issue 15: ``ln(A / A_ref(class, v))``
from a reference curve per superstructure class) is available, the condition
store keeps ``ln(A / 1 m/s²)``: comparable between runs only at matched speed,
which the change detection enforces (:func:`app.analysis.condition.change.speed_matched`).
:func:`app.condition.index.condition_index` is the one place that decides
which index the store holds.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PROVISIONAL_INDEX", "log_amplitude_index"]

#: Name of this index in the provenance of stored rows.
PROVISIONAL_INDEX = "ln_amplitude"


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
