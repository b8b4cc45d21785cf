"""Compiled (numba) kernel of the VKF refinement residual.

The refinement evaluates ``Cᴴ(y − C a − I a*) − Sᵀ(r² ⊙ S a)`` once per step;
in NumPy that is a dozen passes over ``(s, N)`` complex temporaries
(``np.diff``, its padded adjoint, ``einsum``), here one pass per channel with
two length-N work arrays. (A compiled banded Cholesky and back-substitution
were measured too: LAPACK's ``zpbtrf``/``zpbtrs`` are faster at the VKF's band
widths, so the factor stays with LAPACK.)
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["structural_residual"]


@numba.njit(cache=True, nogil=True)
def structural_residual(
    y: np.ndarray,
    expo: np.ndarray,
    image: np.ndarray,
    w: np.ndarray,
    stencil: np.ndarray,
    a: np.ndarray,
    out: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Residual of the (real-signal) VKF normal equations, from the structure.

    ``out = Cᴴ (y − C a − I a*) − Sᵀ (w ⊙ S a)`` per channel.

    Parameters
    ----------
    y : ndarray, complex, shape (channels, N)
    expo : ndarray, complex, shape (s, N)
        Carriers ``exp(jφ)`` (0 where a sample's data equation is left out).
    image : ndarray, complex, shape (s, N) or (0, 0)
        Image carriers; an empty array: no images (Eq. 20).
    w : ndarray, float, shape (s, N − q)
        r² of every row of S.
    stencil : ndarray, float, shape (q + 1,)
        ``(S a)_i = Σ_j stencil[j] a[i + j]``.
    a : ndarray, complex, shape (channels, s, N)
        Current envelopes.
    out : ndarray, complex, shape (channels, s, N)
    """
    c, s, n = a.shape
    q = stencil.shape[0] - 1
    m = n - q
    images = image.shape[0] > 0
    fit = np.empty(n, dtype=np.complex128)
    d = np.empty(m, dtype=np.complex128)
    for ch in range(c):
        for k in range(n):
            fit[k] = y[ch, k]
        for o in range(s):
            if images:
                for k in range(n):
                    ak = a[ch, o, k]
                    fit[k] -= expo[o, k] * ak + image[o, k] * ak.conjugate()
            else:
                for k in range(n):
                    fit[k] -= expo[o, k] * a[ch, o, k]
        for o in range(s):
            for i in range(m):
                acc = 0j
                for j in range(q + 1):
                    acc += stencil[j] * a[ch, o, i + j]
                d[i] = w[o, i] * acc
            for k in range(n):
                acc = expo[o, k].conjugate() * fit[k]
                for i in range(max(0, k - q), min(k, m - 1) + 1):
                    acc -= stencil[k - i] * d[i]
                out[ch, o, k] = acc
