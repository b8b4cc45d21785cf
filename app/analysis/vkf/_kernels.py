"""Compiled (numba) kernels of the banded VKF solve: the band and the refinement residual.

:func:`assemble_band` writes the normal matrix straight into LAPACK's band
storage (NumPy needed a temporary per diagonal and lag). The refinement evaluates ``Cᴴ(y − C a − I a*) − Sᵀ(r² ⊙ S a)`` once per step;
in NumPy that is a dozen passes over ``(s, N)`` complex temporaries
(``np.diff``, its padded adjoint, ``einsum``), here one pass per channel with
two length-N work arrays. (A compiled banded Cholesky and back-substitution
were measured too: LAPACK's ``zpbtrf``/``zpbtrs`` are faster at the VKF's band
widths, so the factor stays with LAPACK.)
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["assemble_band", "structural_residual"]


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


@numba.njit(cache=True, nogil=True)
def assemble_band(expo: np.ndarray, w: np.ndarray, stencil: np.ndarray, ab: np.ndarray) -> None:  # pragma: no cover - compiled
    """Fill the lower band storage of ``Cᴴ C + (R S)ᵀ (R S)`` (time-major unknowns).

    Parameters
    ----------
    expo : ndarray, complex, shape (s, N)
        ``exp(jφ)`` (0 where a sample's data equation is left out).
    w : ndarray, float, shape (s, N − q)
        r² of every row of S.
    stencil : ndarray, float, shape (q + 1,)
    ab : ndarray, complex, shape (q·s + 1, N·s), Fortran order
        Output, ``ab[d, k·s + n] = M[k·s + n + d, k·s + n]``; every entry is written.
    """
    s, n = expo.shape
    q = stencil.shape[0] - 1
    kd = ab.shape[0] - 1
    for k in range(n):
        for o in range(s):
            u = k * s + o
            for d in range(kd + 1):
                ab[d, u] = 0.0
            # Cᴴ C within sample k: M[(k, o+d), (k, o)] = conj(e_{o+d}) e_o
            e = expo[o, k]
            for d in range(s - o):
                ab[d, u] = expo[o + d, k].conjugate() * e
            # (R S)ᵀ (R S): row i of S covers samples i..i+q (weight w[o, i]); samples k and
            # k + lag share the rows i = k − j for j = 0..q − lag (k at stencil position j)
            for lag in range(q + 1):
                if k + lag >= n:
                    break
                acc = 0.0
                for j in range(q - lag + 1):
                    i = k - j
                    if 0 <= i < n - q:
                        acc += stencil[j] * stencil[j + lag] * w[o, i]
                ab[lag * s, u] += acc
