"""THE place that decides which index the segment condition store keeps, and its stated uncertainty.

Everything that writes segment condition rows — the publish step of a job
(:mod:`app.condition.writer`) and the synthetic fleet (``trackvkf simulate-fleet``) — gets
the index of its 25 cm bins from :func:`store_index` and the 1-σ of every segment's index from
:func:`store_index_sd`. The index is the condition index ``ln A``
compared at matched speed (:func:`app.analysis.condition.index.log_amplitude_index`), not the
stiffness index ``ln(A / A_ref(class, v))`` of :mod:`app.analytics.reference_curves`: the
reference curves are re-estimated whenever a run of the line is published, so rows stored with
the stiffness index of their day would move against each other as the curves move, and the
change tests would see the curves' history instead of the track's. The change tests get their
speed conditioning from the matched-speed history and the speed exponent within segments
(:mod:`app.analysis.condition.change`); the stiffness map and ``/analytics/segments?value=index``
show the stiffness index against the current curves.

``index_sd`` is the **stated** 1-σ of the segment's index from the profile's ``sleeper_amp_sd`` and
``sleeper_amp_sd_shared`` (:func:`app.analysis.condition.index.log_amplitude_segment_sd`): what one
pass cannot know about the support (roughness response, noise, too few sleeper bays). It is NaN
(stored NULL) where the profile states none — rows stored before the profiles carried a 1-σ, and the
synthetic fleet, whose noise is a run-to-run repeatability model that the change tests' spread
already measures (stating it again would count it twice).
"""

from __future__ import annotations

import numpy as np

from app.analysis.condition.index import (
    LOG_AMPLITUDE_INDEX,
    log_amplitude_index,
    log_amplitude_segment_sd,
)

__all__ = ["STORE_INDEX", "store_index", "store_index_sd"]

#: Name of the index the store keeps (provenance of its rows and answers).
STORE_INDEX = LOG_AMPLITUDE_INDEX


def store_index(amplitude: np.ndarray) -> np.ndarray:
    """The store's index of 25 cm bins of one wheel (natural log units; NaN where the amplitude is not valid).

    Parameters
    ----------
    amplitude : numpy.ndarray
        Sleeper-passage amplitude, m/s² (NaN where not valid).
    """
    return log_amplitude_index(amplitude)


def store_index_sd(
    position_m: np.ndarray, amplitude: np.ndarray, sd: np.ndarray | None, shared: np.ndarray | None, seg: np.ndarray,
    *, segment_m: float, bin_length_m: float, resolution_m: float = 3.0, filter_order: int = 2,
) -> np.ndarray:
    """The stated 1-σ of the store's index of the segments ``seg`` of one wheel (NaN: none known).

    Parameters
    ----------
    position_m, amplitude : numpy.ndarray
        The wheel's bins: centres on the aligned km axis (m) and amplitude (m/s², NaN where not valid).
    sd, shared : numpy.ndarray or None
        ``sleeper_amp_sd`` and ``sleeper_amp_sd_shared`` of the bins, m/s² (None or NaN: not stated).
    seg : numpy.ndarray
        The segments to answer (int, e.g. :attr:`~app.analysis.condition.SegmentStats.seg`).
    segment_m, bin_length_m : float
        m.
    resolution_m, filter_order : optional
        The track orders' resolution (m) and q of the job's processing settings.

    Returns
    -------
    numpy.ndarray
        (len(seg),) natural log units.
    """
    s = np.asarray(seg, dtype=np.int64)
    out = np.full(s.size, np.nan)
    segs, sd_seg = log_amplitude_segment_sd(position_m, amplitude, sd, shared, segment_m=segment_m,
                                            bin_length_m=bin_length_m, resolution_m=resolution_m,
                                            filter_order=filter_order)
    if segs.size and s.size:
        j = np.minimum(np.searchsorted(segs, s), segs.size - 1)
        hit = segs[j] == s
        out[hit] = sd_seg[j[hit]]
    return out
