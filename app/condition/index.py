"""THE place that decides which index the segment condition store keeps: the condition index.

Everything that writes segment condition rows — the publish step of a job
(:mod:`app.condition.writer`) and the synthetic fleet (``trackvkf simulate-fleet``) — gets
the index of its 25 cm bins from :func:`store_index`. It is the condition index ``ln A``
compared at matched speed (:func:`app.analysis.condition.index.log_amplitude_index`), not the
stiffness index ``ln(A / A_ref(class, v))`` of :mod:`app.analytics.reference_curves`: the
reference curves are re-estimated whenever a run of the line is published, so rows stored with
the stiffness index of their day would move against each other as the curves move, and the
change tests would see the curves' history instead of the track's. The change tests get their
speed conditioning from the matched-speed history and the speed exponent within segments
(:mod:`app.analysis.condition.change`); the stiffness map and ``/analytics/segments?value=index``
show the stiffness index against the current curves.
"""

from __future__ import annotations

import numpy as np

from app.analysis.condition.index import LOG_AMPLITUDE_INDEX, log_amplitude_index

__all__ = ["STORE_INDEX", "store_index"]

#: Name of the index the store keeps (provenance of its rows and answers).
STORE_INDEX = LOG_AMPLITUDE_INDEX


def store_index(amplitude: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The store's index of 25 cm bins of one wheel and its uncertainty (natural log units).

    Parameters
    ----------
    amplitude : numpy.ndarray
        Sleeper-passage amplitude, m/s² (NaN where not valid).

    Returns
    -------
    index, index_sd : numpy.ndarray
        Per bin (NaN where the amplitude is not valid).
    """
    return log_amplitude_index(amplitude)
