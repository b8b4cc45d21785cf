"""Independent, deliberately simple reference of the multi-order VKF (paper Eq. 20).

Written from the paper and the engine contract only, for small problems:
the sparse matrices are built exactly as the paper writes them and the
normal equations are solved with SuperLU (``scipy.sparse.linalg.splu``, the
factorisation behind ``spsolve``). No decimation, no chunking, no tricks --
except that the normal equations are badly conditioned (1e10-1e12 for q = 3
with close orders), so a plain double-precision solve is only good to ~1e-6;
by default a few steps of iterative refinement with the residual computed in
extended precision (``np.clongdouble``) bring the solution to ~1e-10.

The bandwidth -> weight conversion lives in :func:`weight_from_bandwidth`,
separate from the solver (the solver takes the weights r).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy.sparse.linalg import splu
from scipy.special import comb

__all__ = [
    "difference_matrix",
    "reference_vkf",
    "reference_objective",
    "weight_from_bandwidth",
    "stationary_response",
    "carrier_phase",
]


def carrier_phase(freqs: ArrayLike, fs: float, phase0: ArrayLike | None = None) -> np.ndarray:
    """``phase0 + 2*pi*cumsum(freqs, axis=-1)/fs`` (contract / paper Eq. 3), rad."""
    f = np.atleast_2d(np.asarray(freqs, dtype=float))
    phi = 2.0 * np.pi * np.cumsum(f, axis=-1) / fs
    if phase0 is not None:
        phi = phi + np.asarray(phase0, dtype=float).reshape(-1, 1)
    return phi


def difference_matrix(n_samples: int, q: int) -> sp.csr_matrix:
    """The (N-q) x N q-th difference matrix S_q.

    Row k (k = 0..N-q-1) is the binomial stencil over samples k..k+q, i.e. the
    difference that *ends* at sample i = k + q (contract: rows i = q..N-1).
    """
    m = n_samples - q
    diagonals = [(-1.0) ** (q - j) * comb(q, j, exact=True) * np.ones(m) for j in range(q + 1)]
    return sp.diags(diagonals, offsets=list(range(q + 1)), shape=(m, n_samples), format="csr")


def _full_weights(r: ArrayLike, s: int, n_samples: int) -> np.ndarray:
    r = np.asarray(r, dtype=float)
    if r.ndim == 0:
        return np.full((s, n_samples), float(r))
    if r.shape == (s,):
        return np.repeat(r[:, None], n_samples, axis=1)
    if r.shape == (s, n_samples):
        return r
    raise ValueError(f"r must be scalar, ({s},) or ({s}, {n_samples}); got {r.shape}")


def reference_vkf(
    y: ArrayLike, phi: ArrayLike, r: ArrayLike, q: int, *, refine: int = 4
) -> np.ndarray:
    """Solve ``[C^H C + (R S)^T (R S)] a = C^H y`` for the complex envelopes A.

    Parameters
    ----------
    y : array_like, shape (N,)
        Real signal.
    phi : array_like, shape (s, N)
        Carrier phase of each order, rad.
    r : float or array_like, shape (s,) or (s, N)
        Weights. For an (s, N) array, row i (i = q..N-1) of the difference
        matrix of order n is weighted by ``r[n, i]``.
    q : int
        Order of the difference operator (1, 2 or 3).
    refine : int
        Steps of iterative refinement with an extended-precision residual
        (0 = the plain double-precision sparse solve).

    Returns
    -------
    ndarray, shape (s, N), complex
        The paper's A_n (the engine's envelope is ``2 A``).
    """
    y = np.asarray(y, dtype=float)
    phi = np.atleast_2d(np.asarray(phi, dtype=float))
    s, n = phi.shape
    assert y.shape == (n,)
    w = _full_weights(r, s, n)[:, q:].reshape(-1)
    lhs, rhs = _normal_equations(y, phi, w, q, float)
    lu = splu(lhs.tocsc())
    a = lu.solve(rhs)
    if refine:
        lhs_x, rhs_x = _normal_equations(y, phi, w, q, np.longdouble)
        a_x = a.astype(np.clongdouble)
        for _ in range(refine):
            a_x = a_x + lu.solve((rhs_x - lhs_x @ a_x).astype(complex))
        a = a_x.astype(complex)
    return np.asarray(a).reshape(s, n)


def _normal_equations(y, phi, w, q, real_dtype):
    """``C^H C + (R S)^T (R S)`` and ``C^H y`` in the given precision."""
    s, n = phi.shape
    phi = phi.astype(real_dtype)
    # C = [C_1 C_2 ... C_s], C_n = diag(exp(j phi_n))
    c = sp.hstack([sp.diags(np.exp(1j * phi[k])) for k in range(s)], format="csr")
    # S = I_s (x) S_q ; R = diag of one weight per row of S
    s_big = sp.kron(sp.identity(s, format="csr"), difference_matrix(n, q), format="csr")
    rs = sp.diags(w.astype(real_dtype)) @ s_big.astype(real_dtype)
    lhs = (c.conj().T @ c + rs.T @ rs).tocsr()
    rhs = c.conj().T @ y.astype(real_dtype)
    return lhs, rhs


def reference_objective(y: ArrayLike, phi: ArrayLike, r: ArrayLike, q: int, a: np.ndarray) -> float:
    """Objective of paper Eq. 19 for envelopes ``a`` (s, N), computed with np.diff."""
    y = np.asarray(y, dtype=float)
    phi = np.atleast_2d(np.asarray(phi, dtype=float))
    s, n = phi.shape
    eta = y - np.sum(a * np.exp(1j * phi), axis=0)
    w = _full_weights(r, s, n)[:, q:]
    reg = w * np.diff(a, n=q, axis=-1)
    return float(np.sum(np.abs(eta) ** 2) + np.sum(np.abs(reg) ** 2))


def weight_from_bandwidth(bandwidth: ArrayLike, fs: float, q: int) -> np.ndarray:
    """Weight r for a full -3 dB bandwidth (Hz) at sample rate fs (Hz), order q.

    ``r = sqrt(sqrt(2) - 1) / (2 sin(pi B / (2 fs)))**q``, so that the
    stationary response ``1 / (1 + r^2 (2 sin(w/2))^(2q))`` is 1/sqrt(2) at an
    offset of B/2 Hz.
    """
    b = np.asarray(bandwidth, dtype=float)
    return np.sqrt(np.sqrt(2.0) - 1.0) / (2.0 * np.sin(np.pi * b / (2.0 * fs))) ** q


def stationary_response(offset_hz: ArrayLike, bandwidth: float, fs: float, q: int) -> np.ndarray:
    """Amplitude response of a single-order VKF to a tone offset by ``offset_hz``."""
    r = weight_from_bandwidth(bandwidth, fs, q)
    w = 2.0 * np.pi * np.asarray(offset_hz, dtype=float) / fs
    return 1.0 / (1.0 + r**2 * (2.0 * np.sin(w / 2.0)) ** (2 * q))
