"""Multi-order Vold–Kalman filter (VKF) order tracking: the public numerical API.

The VKF (Hoelzl et al., paper Eqs. 1–20) models a measured signal as a sum of ``s`` orders with
slowly varying complex envelopes and finds all envelopes jointly (docs/vkf.md). The package:

- :mod:`~app.analysis.vkf.engine`: the API below, the chunked solve and its crossfade;
- private solvers: ``_input`` (the input checked and scanned), ``_baseband`` (mixing to complex
  baseband and decimation), ``_banded`` (the coupled normal equations as one banded Hermitian
  matrix, iterative refinement), ``_kernels`` (its compiled assembly and residual),
  ``_stationary`` (the stationary-frequency fit), ``_weights`` (the bandwidth ↔ weight relation and
  the impulse-response length).

Public API (documented with an example in docs/vkf.md)
-----------------------------------------------------
vkf, vkf_stream, vkf_overlap, VKFResult, VKFWarning. Order tracks of railway data
(``OrderTrack``, ``wheel_orders``, ``sleeper_passage``) live in :mod:`app.analysis.orders`.
"""

from app.analysis.vkf.engine import (
    CLOSE_ORDERS_MESSAGE,
    VKFResult,
    VKFWarning,
    vkf,
    vkf_overlap,
    vkf_stream,
)

__all__ = ["vkf", "vkf_stream", "vkf_overlap", "VKFResult", "VKFWarning", "CLOSE_ORDERS_MESSAGE"]
