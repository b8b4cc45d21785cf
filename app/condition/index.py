"""THE place that decides the condition index of the store's segment rows.

Everything that writes segment condition rows — the publish step of a job
(:mod:`app.condition.writer`) and the synthetic fleet (``trackvkf
simulate-fleet``) — gets the index of its 25 cm bins from
:func:`condition_index`. It is ``ln A`` compared at matched speed
(:func:`app.analysis.condition.index.log_amplitude_index`), not the stiffness
index ``ln(A / A_ref(class, v))`` of :mod:`app.analytics.reference_curves`: the
reference curves are re-estimated whenever a run of the line is published, so
rows stored with the index of their day would move against each other as the
curves move, and the change tests would see the curves' history instead of the
track's. The change tests get their speed conditioning from the matched-speed
history and the speed exponent within segments (:mod:`app.analysis.condition.change`);
the stiffness map and ``/analytics/segments?value=index`` show the index against
the current curves.
"""

from __future__ import annotations

import numpy as np
from sqlalchemy.orm import Session

from app.analysis.condition.index import PROVISIONAL_INDEX, log_amplitude_index

__all__ = ["condition_index", "index_name"]


def index_name(session: Session, line_id: str, track: str) -> str:  # noqa: ARG001 - the curve will depend on them
    """Name of the index :func:`condition_index` gives for a line (provenance of the rows)."""
    return PROVISIONAL_INDEX


def condition_index(
    session: Session,  # noqa: ARG001 - the reference curve of the line will be read here
    line_id: str,  # noqa: ARG001
    track: str,  # noqa: ARG001
    position_m: np.ndarray,  # noqa: ARG001 - the superstructure class is looked up by position
    amplitude: np.ndarray,
    speed_mps: np.ndarray,  # noqa: ARG001 - the reference curve is a function of speed
) -> tuple[np.ndarray, np.ndarray]:
    """Condition index of 25 cm bins of one wheel and its uncertainty (natural log units).

    Parameters
    ----------
    session : Session
        Database session (to read the line's reference curve and sections).
    line_id, track : str
        The line and track of the run.
    position_m : numpy.ndarray
        Bin centres on the aligned km axis, m.
    amplitude : numpy.ndarray
        Sleeper-passage amplitude, m/s² (NaN where not valid).
    speed_mps : numpy.ndarray
        Speed, m/s.

    Returns
    -------
    index, index_sd : numpy.ndarray
        Per bin (NaN where the amplitude is not valid).
    """
    return log_amplitude_index(amplitude)
