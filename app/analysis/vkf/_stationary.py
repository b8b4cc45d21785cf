"""Stationary orders: envelopes that depend on their own frequency only.

Some orders come from a source that does not change along the record — a
wheel's out-of-roundness, a rotor's unbalance: its response changes with the
excitation frequency (the speed moves it along the structure's frequency
response), never with time or place. Solved as an ordinary narrow order next
to a wide one whose band holds it, such an order takes every piece of the wide
order's changes that falls on its line — in a joint least-squares solve an
order has no structural penalty at its own line, whatever its bandwidth, so
its estimate is the projection of the signal on the line over the filter's
memory — and the wide order loses that piece: a beat between the two orders
that decays over the narrow filter's memory. On railway data the sleeper
passage (wide, a 3 m spatial resolution) holds wheel order 5 in its band; a
stiffness step rang at 11–14 % of the step over ~30 m (issue 26).

A segment with stationary orders is therefore solved in three steps:

1. every order at the stationary orders' (narrowest) bandwidth, Eq. 20 as
   written (equal narrow bands reject the mirror images): the lines separated
   by frequency. All orders take part, not only those near the stationary
   ones: at a record's ends a narrow filter sees one side only and a strong
   line one order away (a wheel polygon) would otherwise leak in;
2. each stationary envelope is replaced by its **function of frequency**: a
   local-linear regression over log-frequency with a Gaussian kernel
   :data:`STATIONARY_KERNEL_REL` wide (:func:`fit_over_log_frequency`). At a
   steady frequency that is one phasor over the whole segment, so what the
   other orders' changes put on the line averages out over the segment
   (falling like 1/length) instead of staying with the line locally;
3. the orders wider than the stationary ones are solved again at their own
   bandwidths, with the real-signal model if asked, on the baseband signal
   less every other order's component (and mirror image); the other narrow
   orders keep their step-1 envelopes.

Why the kernel is 1 % of the frequency wide: at a steady speed (a train holds
its speed within ~1 %) the whole segment counts, which is what removes the
wide order's share; where the frequency runs up or down, only the samples
within ±1 % of it count, so the fit still follows a response that changes with
frequency (a resonance of the wheel–track system) — there it is about as local
as the narrow filter itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ._banded import BandedSolution, solve_orders

__all__ = ["STATIONARY_KERNEL_REL", "LogFrequencyFit", "fit_over_log_frequency", "solve_with_stationary"]

#: width (1 σ) of the Gaussian kernel over log-frequency of the stationary fit, relative frequency
STATIONARY_KERNEL_REL = 0.01
#: bins per kernel σ
_BINS_PER_SIGMA = 4
#: kernel truncation, σ
_KERNEL_SIGMAS = 4.0


@dataclass(frozen=True)
class LogFrequencyFit:
    """Complex envelopes as a local-linear function of log-frequency.

    Attributes
    ----------
    log_f0 : float
        ln of the frequency (Hz) of bin 0.
    step : float
        Bin width, ln-frequency.
    a, b : ndarray, complex, shape (channels, n_bins)
        Value at each bin centre and slope per unit ln-frequency.
    """

    log_f0: float
    step: float
    a: np.ndarray
    b: np.ndarray

    def __call__(self, freq: np.ndarray) -> np.ndarray:
        """Values at frequencies (Hz, > 0), shape (channels, len(freq)); frequencies beyond
        the fitted range take the nearest bin's line."""
        ln = np.log(np.maximum(np.asarray(freq, dtype=np.float64), np.finfo(float).tiny))
        j = np.clip(np.rint((ln - self.log_f0) / self.step), 0, self.a.shape[1] - 1).astype(np.int64)
        d = ln - (self.log_f0 + j * self.step)
        return self.a[:, j] + self.b[:, j] * d[None, :]


def fit_over_log_frequency(values: np.ndarray, freq: np.ndarray, mask: np.ndarray,
                           rel_width: float = STATIONARY_KERNEL_REL) -> LogFrequencyFit | None:
    """Local-linear kernel regression of complex envelopes over log-frequency.

    At every frequency ``f`` the value ``a`` and slope ``b`` minimise
    ``Σ_k K(ln f_k − ln f) |values_k − a − b (ln f_k − ln f)|²`` with a
    Gaussian ``K`` of σ ``rel_width``; the sums are gathered on bins a quarter
    of σ wide and convolved with the kernel. Where (nearly) every sample has
    one frequency the slope is undetermined and a small ridge holds it at 0:
    the fit is then the mean.

    Parameters
    ----------
    values : ndarray, complex, shape (channels, M)
    freq : ndarray, shape (M,)
        Frequency at the samples, Hz.
    mask : ndarray of bool, shape (M,)
        Samples that count.
    rel_width : float
        Kernel σ, relative frequency (> 0).

    Returns
    -------
    LogFrequencyFit or None
        None when no sample counts.
    """
    if not rel_width > 0:
        raise ValueError(f"rel_width must be > 0, got {rel_width!r}")
    vals = np.atleast_2d(np.asarray(values, dtype=np.complex128))
    f = np.asarray(freq, dtype=np.float64)
    ok = np.asarray(mask, dtype=bool) & (f > 0) & np.all(np.isfinite(vals), axis=0)
    if not np.any(ok):
        return None
    ln = np.log(f[ok])
    vals = vals[:, ok]
    step = rel_width / _BINS_PER_SIGMA
    lo = float(ln.min())
    j = np.rint((ln - lo) / step).astype(np.int64)
    nb = int(j.max()) + 1
    d = ln - (lo + j * step)

    def gather(w: np.ndarray) -> np.ndarray:
        return np.bincount(j, w, minlength=nb)

    s0, s1, s2 = gather(np.ones_like(d)), gather(d), gather(d * d)
    t0 = np.stack([gather(v.real) + 1j * gather(v.imag) for v in vals])
    t1 = np.stack([gather(d * v.real) + 1j * gather(d * v.imag) for v in vals])
    half = int(math.ceil(_KERNEL_SIGMAS * _BINS_PER_SIGMA))
    off = np.arange(-half, half + 1)
    k0 = np.exp(-0.5 * (off / _BINS_PER_SIGMA) ** 2)
    dk = off * step  # source bin centre minus target bin centre

    def corr(x: np.ndarray, kern: np.ndarray) -> np.ndarray:
        # target c gathers source c + off[i] with kern[i]
        full = np.convolve(x.real, kern[::-1]) + (1j * np.convolve(x.imag, kern[::-1]) if np.iscomplexobj(x) else 0)
        return full[half : half + nb]

    # moments about each target bin centre (a sample's offset there is d + dk)
    m0 = corr(s0, k0).real
    m1 = (corr(s1, k0) + corr(s0, k0 * dk)).real
    m2 = (corr(s2, k0) + 2.0 * corr(s1, k0 * dk) + corr(s0, k0 * dk * dk)).real
    m2 = m2 + 1e-6 * rel_width**2 * m0  # ridge: a single-frequency stretch has slope 0
    n0 = np.stack([corr(t, k0) for t in t0])
    n1 = np.stack([corr(t1[c], k0) + corr(t0[c], k0 * dk) for c in range(vals.shape[0])])
    det = m0 * m2 - m1 * m1
    good = (m0 > 1e-12 * m0.max()) & (det > 0)
    safe = np.where(good, det, 1.0)
    a = np.where(good, (m2 * n0 - m1 * n1) / safe, 0.0)
    b = np.where(good, (m0 * n1 - m1 * n0) / safe, 0.0)
    return LogFrequencyFit(log_f0=lo, step=step, a=a, b=b)


def solve_with_stationary(
    ys: np.ndarray,
    phi: np.ndarray,
    f: np.ndarray,
    bw: np.ndarray,
    r2: np.ndarray,
    weights: Callable[[np.ndarray], np.ndarray],
    q: int,
    data_mask: np.ndarray | None,
    image: np.ndarray | None,
    stationary: np.ndarray,
) -> BandedSolution:
    """Solve a segment whose ``stationary`` orders are functions of their frequency (steps 1–3).

    Parameters
    ----------
    ys : ndarray, complex, shape (channels, m)
        Segment at the solve rate (baseband when decimated).
    phi : ndarray, shape (s, m)
        Carrier phases there (mixing removed), rad.
    f, bw : ndarray, shape (s, m)
        Order frequencies and bandwidths, Hz.
    r2 : ndarray, shape (s, m − q)
        Weights of every order at its own bandwidth.
    weights : callable
        r² for a bandwidth array of shape (k, m − q), Hz (clipped like ``r2``).
    q : int
    data_mask : ndarray of bool, shape (m,), optional
        Samples whose data equation is used.
    image : ndarray, complex, shape (s, m), optional
        Mirror-image carriers (the real-signal model); None: Eq. 20.
    stationary : ndarray of bool, shape (s,)

    Returns
    -------
    BandedSolution
        Envelopes of every order (the paper's A): the stationary ones fitted over
        frequency, the orders wider than them from step 3, the others from step 1.
    """
    floor = bw[stationary].min(axis=0)
    wide = ~stationary & np.any(bw > floor[None, :] * (1.0 + 1e-9), axis=1)
    narrow = np.minimum(bw, floor[None, :])
    narrow[stationary] = bw[stationary]
    sol1 = solve_orders(ys, phi, weights(narrow[:, q:]), q, data_mask, None)
    env = sol1.envelope.copy()
    used = np.ones(phi.shape[1], dtype=bool) if data_mask is None else np.asarray(data_mask, dtype=bool)
    for n in np.flatnonzero(stationary):
        valid = f[n] >= bw[n]
        fit = fit_over_log_frequency(env[:, n], f[n], used & valid)
        if fit is not None:
            env[:, n] = np.where(valid[None, :], fit(f[n]), env[:, n])
    if not wide.any():
        return BandedSolution(envelope=env, iterations=sol1.iterations, correction=sol1.correction,
                              shifted=sol1.shifted)
    fixed = np.flatnonzero(~wide)
    rest = np.array(ys, dtype=np.complex128)
    rest -= np.einsum("cnm,nm->cm", env[:, fixed], np.exp(1j * phi[fixed]))
    if image is not None:
        rest -= np.einsum("cnm,nm->cm", env[:, fixed].conj(), image[fixed])
    sol2 = solve_orders(rest, phi[wide], r2[wide], q, data_mask, None if image is None else image[wide])
    env[:, wide] = sol2.envelope
    return BandedSolution(envelope=env, iterations=sol1.iterations + sol2.iterations,
                          correction=max(sol1.correction, sol2.correction), shifted=sol1.shifted or sol2.shifted,
                          images_dropped=sol2.images_dropped)
