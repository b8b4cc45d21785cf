"""Banded Hermitian solver of the coupled multi-order VKF normal equations.

The normal equations of the paper (Eq. 20),

    [Cᴴ C + (R S)ᵀ (R S)] a = Cᴴ y,

are assembled with the unknowns ordered *time-major* (``u = k*s + n`` for
sample ``k`` and order ``n``). In that order ``Cᴴ C`` is block diagonal with
dense ``s x s`` blocks and ``(R S)ᵀ (R S)`` couples sample ``k`` with samples
``k ± 1 … k ± q`` of the same order, so the matrix is Hermitian positive
definite with ``q*s`` sub-diagonals. It is factored once with LAPACK's banded
Cholesky (``zpbtrf``) and solved for every channel at once (``zpbtrs``).

Narrow bandwidths at high sample rates make the weights huge (r² ≈ 10¹³ at
1.5 Hz / 12 kHz, q = 2): the unit diagonal of ``Cᴴ C`` then survives in the
assembled matrix to only a few bits and a plain solve is biased. The factor
is therefore only used as a preconditioner of *iterative refinement* whose
residual is computed from the structure, never from the assembled matrix:
``Cᴴ (y − C a)`` and ``Sᵀ (r² ⊙ (S a))`` with exact finite differences of the
current iterate. Each step removes the factorisation error by a factor of
about ``eps·r²·4^q``; the loop stops when the estimated error left (last correction times the
observed convergence rate) is below 1e-13.

The measured signal is real, so every order also appears as its mirror image
``conj(A_n)·exp(−jφ_n)``, which Eq. 20 leaves in the noise term. A narrow
filter rejects it, but a wide order solved next to a narrow one (the track
orders beside the wheel orders) does not: the coupled solve turns the images
into errors of ~1 % inside a record and 10–25 % at its ends. Given the images'
carriers (``image``), the same refinement solves the real-signal model
``y = Σ_n A_n·exp(jφ_n) + g_n·conj(A_n)·exp(−jφ_n′)`` instead: its residual
subtracts the images of the current iterate, so the fixed point reproduces a
real signal made of the orders exactly. That fixed point converges only
linearly (rate ≈ 0.2 for the railway recipe, the slow modes at the record
ends), so its steps are Anderson-accelerated (type II, depth
``_ANDERSON_DEPTH``: each step mixes the last few corrections by a small least
squares per channel; for a linear map this is GMRES in disguise): 6–7
back-substitutions instead of 15 for the same 1e-10. The plain refinement
needs no acceleration (rate ≈ eps·r²·4^q).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgError
from scipy.linalg.lapack import zpbtrf, zpbtrs
from scipy.special import comb
from threadpoolctl import threadpool_limits

from ._kernels import assemble_band, structural_residual

__all__ = ["BandedSolution", "solve_orders"]

_EPS = np.finfo(np.float64).eps
_REFINE_TOL = 1e-13
#: stop of the refinement when it also carries the mirror images: a linear
#: fixed point (rate ~0.05–0.15), run to far below any use of the envelopes
_IMAGE_TOL = 1e-10
_REFINE_MAX_ITER = 60
#: corrections the Anderson-accelerated image refinement mixes (2 and 6 converge alike)
_ANDERSON_DEPTH = 2
#: "no image carriers" for the compiled residual
_NO_IMAGE = np.zeros((0, 0), dtype=np.complex128)


@dataclass(frozen=True)
class BandedSolution:
    """Envelopes of one solve and how the solve went.

    Attributes
    ----------
    envelope : ndarray, complex, shape (channels, s, N)
        Paper's complex envelopes ``A_n[k]`` (half the peak amplitude).
    iterations : int
        Refinement steps taken after the first solve.
    correction : float
        Estimated relative error left after the last refinement step
        (last correction times the observed convergence rate).
    shifted : bool
        True if the factorisation needed a diagonal shift to stay positive
        definite (refinement then removes the shift's effect).
    images_dropped : bool
        True if the mirror images were asked for but their refinement did
        not contract (a record far too short for its narrowest filter): the
        envelopes are then those of Eq. 20, images left in the noise.
    """

    envelope: np.ndarray
    iterations: int
    correction: float
    shifted: bool
    images_dropped: bool = False


def _stencil(q: int) -> np.ndarray:
    """Coefficients c_j (j = 0..q) of the q-th backward difference over samples i-q..i."""
    j = np.arange(q + 1)
    return (-1.0) ** (q - j) * comb(q, j, exact=False)


def _assemble(expo: np.ndarray, w: np.ndarray, q: int) -> np.ndarray:
    """Lower band storage ``ab[d, j] = M[j + d, j]`` of the normal matrix.

    Parameters
    ----------
    expo : ndarray, complex, shape (s, N)
        ``exp(j*phi_n[k])``.
    w : ndarray, float, shape (s, N - q)
        Squared weights r² of every row of S.
    q : int
        Difference order.

    Notes
    -----
    ``Cᴴ C`` couples the orders within one sample, ``M[(k, n+d), (k, n)] =
    conj(c_{n+d}) c_n``; ``(R S)ᵀ (R S)`` adds the lag-δ products of the
    stencil, weighted by the rows that contain both samples. Filled in one
    compiled pass (:func:`._kernels.assemble_band`), in Fortran order as
    LAPACK wants it: ``zpbtrf`` then factorises in place instead of copying
    the largest array of the solve.
    """
    s, n = expo.shape
    ab = np.empty((n * s, q * s + 1), dtype=np.complex128).T
    assemble_band(np.ascontiguousarray(expo), np.ascontiguousarray(w, dtype=np.float64), _stencil(q), ab)
    return ab


def _residual(
    y: np.ndarray, expo: np.ndarray, w: np.ndarray, q: int, a: np.ndarray, image: np.ndarray | None = None
) -> np.ndarray:
    """Residual of the normal equations, computed from the structure.

    ``Cᴴ (y − C a − I a*) − (R S)ᵀ (R S) a`` for a of shape (channels, s, N)
    and y of shape (channels, N); ``I`` the image carriers (none: ``I = 0``).
    One compiled pass per channel (:func:`._kernels.structural_residual`).
    """
    out = np.empty_like(a)
    structural_residual(y, expo, _NO_IMAGE if image is None else image, w, _stencil(q), a, out)
    return out


def _to_band(x: np.ndarray) -> np.ndarray:
    """(channels, s, N) → (N*s, channels), time-major."""
    c, s, n = x.shape
    return np.ascontiguousarray(x.transpose(2, 1, 0).reshape(n * s, c))


def _from_band(x: np.ndarray, s: int) -> np.ndarray:
    """(N*s, channels) → (channels, s, N)."""
    ns, c = x.shape
    return np.ascontiguousarray(x.reshape(ns // s, s, c).transpose(2, 1, 0))


def _factor(assemble: Callable[[], np.ndarray]) -> tuple[np.ndarray, bool]:
    """Banded Cholesky (LAPACK zpbtrf) in place; on breakdown retry with a diagonal shift.

    ``assemble()`` returns the band matrix; it is factorised in place (the
    band is the largest array of a solve) and rebuilt for each retry.
    The shift only changes the preconditioner: refinement still converges to
    the solution of the unshifted equations while the shift stays below ~1.
    """
    chol, info = zpbtrf(assemble(), lower=1, overwrite_ab=1)
    if info == 0:
        return chol, False
    del chol
    for factor in (1e2, 1e4, 1e6, 1e8):
        shifted = assemble()
        shifted[0] += factor * _EPS * float(np.max(shifted[0].real))
        chol, info = zpbtrf(shifted, lower=1, overwrite_ab=1)
        if info == 0:
            return chol, True
        del chol, shifted
    raise LinAlgError("VKF normal matrix is not positive definite even with a diagonal shift")


def _cho_solve(chol: np.ndarray, rhs: np.ndarray, s: int) -> np.ndarray:
    """Solve with the banded factor for (channels, s, N) right-hand sides."""
    x, info = zpbtrs(chol, _to_band(rhs), lower=1)
    if info != 0:  # pragma: no cover - zpbtrs only fails on bad arguments
        raise LinAlgError(f"zpbtrs failed with info={info}")
    return _from_band(x, s)


def solve_orders(
    y: np.ndarray,
    phi: np.ndarray,
    r2: np.ndarray,
    q: int,
    data_mask: np.ndarray | None = None,
    image: np.ndarray | None = None,
) -> BandedSolution:
    """Solve the coupled VKF least-squares problem for every channel.

    Parameters
    ----------
    y : ndarray, shape (channels, N), real or complex
        Observed signal (complex for baseband input).
    phi : ndarray, shape (s, N)
        Phase of every order at every sample, rad.
    r2 : ndarray, shape (s, N - q)
        Squared weight of every row of the difference operator.
    q : int
        Difference order, 1–3.
    data_mask : ndarray of bool, shape (N,), optional
        Samples whose data equation is used (default all). Samples left out
        (e.g. where a decimation filter ran over the segment ends) get their
        envelopes from the structural equation alone.
    image : ndarray, complex, shape (s, N), optional
        Carrier of every order's mirror image in ``y``, ``g_n·exp(−jφ_n′)``
        (a real signal at full rate: ``exp(−jφ_n)``); the image of order ``n``
        is ``image[n]·conj(A_n)``. None: the images count as noise (Eq. 20).

    Returns
    -------
    BandedSolution
    """
    # Banded LAPACK kernels are memory bound with tiny inner loops: extra BLAS
    # threads only add synchronisation (10x slower on 2 cores), so use one.
    with threadpool_limits(limits=1, user_api="blas"):
        return _solve(y, phi, r2, q, data_mask, image)


def _solve(
    y: np.ndarray,
    phi: np.ndarray,
    r2: np.ndarray,
    q: int,
    data_mask: np.ndarray | None,
    image: np.ndarray | None,
) -> BandedSolution:
    s, n = phi.shape
    if n <= q:
        raise ValueError(f"need more than filter_order={q} samples, got {n}")
    # C enters only the data term: a zero column removes that sample's data
    # equation from Cᴴ C, from Cᴴ y and from the refinement residual.
    expo = np.exp(1j * phi)
    if data_mask is not None:
        expo[:, ~np.asarray(data_mask, dtype=bool)] = 0.0
        if image is not None:
            image = np.where(np.asarray(data_mask, dtype=bool)[None, :], image, 0.0)
    w = np.ascontiguousarray(r2, dtype=np.float64)
    yc = np.ascontiguousarray(y, dtype=np.complex128)
    chol, shifted = _factor(lambda: _assemble(expo, w, q))

    a = _cho_solve(chol, expo.conj()[None, :, :] * yc[:, None, :], s)
    norm_a = max(float(np.linalg.norm(a)), np.finfo(float).tiny)
    images_dropped = False
    if image is None:
        it, correction, _ = _refine(chol, yc, expo, w, q, a, None, _REFINE_TOL, norm_a)
    else:
        image = np.ascontiguousarray(image, dtype=np.complex128)
        it, correction, ok = _refine(chol, yc, expo, w, q, a, image, _IMAGE_TOL, norm_a)
        if not ok:  # start again from the plain solve: Eq. 20, images left in the noise
            a = _cho_solve(chol, expo.conj()[None, :, :] * yc[:, None, :], s)
            it_plain, correction, _ = _refine(chol, yc, expo, w, q, a, None, _REFINE_TOL, norm_a)
            it += it_plain
            images_dropped = True
    return BandedSolution(envelope=a, iterations=it, correction=correction, shifted=shifted,
                          images_dropped=images_dropped)


def _anderson_mix(inc: np.ndarray, f: np.ndarray, dx: list[np.ndarray], df: list[np.ndarray]) -> None:
    """Turn the fixed-point step ``inc = f`` into the Anderson step, in place, per channel.

    ``γ = argmin ‖f − Σ_i γ_i Δf_i‖`` (real coefficients: the image term makes
    the map real-linear, not complex-linear), ``inc = f − Σ_i γ_i (Δx_i + Δf_i)``.
    """
    m = len(df)
    for ch in range(f.shape[0]):
        gram = np.empty((m, m))
        rhs = np.empty(m)
        for i in range(m):
            rhs[i] = np.vdot(df[i][ch], f[ch]).real
            for j in range(i, m):
                gram[i, j] = gram[j, i] = np.vdot(df[i][ch], df[j][ch]).real
        scale = float(np.max(np.diag(gram)))
        if not scale > 0.0:
            continue
        gram[np.diag_indices(m)] += 1e-12 * scale  # the differences may be nearly dependent
        try:
            gamma = np.linalg.solve(gram, rhs)
        except np.linalg.LinAlgError:  # pragma: no cover - guarded by the shift above
            continue
        for g, dxi, dfi in zip(gamma, dx, df, strict=True):
            inc[ch] -= g * (dxi[ch] + dfi[ch])


def _refine(
    chol: np.ndarray,
    y: np.ndarray,
    expo: np.ndarray,
    w: np.ndarray,
    q: int,
    a: np.ndarray,
    image: np.ndarray | None,
    tol: float,
    norm_a: float,
) -> tuple[int, float, bool]:
    """Iterative refinement of ``a`` in place; with images Anderson-accelerated.

    Each step solves the factor for the structural residual, ``f = M̃⁻¹ r(a)``.
    The iteration converges linearly: each correction is the previous one
    times a rate rho (eps · cond; with the images also their coupling). The
    first solve counts as a correction of relative size 1, so after a
    correction c_k the error left is about c_k · (c_k / c_{k-1}); it stops as
    soon as that estimate is below ``tol``.

    Returns
    -------
    (steps, estimated error left, converging)
    """
    s = expo.shape[0]
    depth = 0 if image is None else _ANDERSON_DEPTH
    dx: list[np.ndarray] = []
    df: list[np.ndarray] = []
    f_prev: np.ndarray | None = None
    inc_prev: np.ndarray | None = None
    correction, prev, best, it = np.inf, 1.0, np.inf, 0
    for it in range(1, _REFINE_MAX_ITER + 1):  # noqa: B007 - used after loop
        f = _cho_solve(chol, _residual(y, expo, w, q, a, image), s)
        step = float(np.linalg.norm(f)) / norm_a
        if image is not None and (not np.isfinite(step) or (it > 3 and step > prev and step > best)):
            return it, correction, False  # the image coupling is no contraction here
        correction = step * min(step / prev, 1.0)
        if depth:
            if f_prev is not None and inc_prev is not None:
                dx.append(inc_prev)
                df.append(f - f_prev)
                if len(dx) > depth:
                    del dx[0], df[0]
            f_prev = f
            inc = f.copy()
            if df:
                _anderson_mix(inc, f, dx, df)
            a += inc
            inc_prev = inc
        else:
            a += f
        if correction <= tol:
            break
        if step > prev * 0.999 and step < 1e-9:
            break  # stagnated at rounding level
        best = min(best, step)
        prev = step
    return it, correction, True
