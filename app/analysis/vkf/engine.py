"""The VKF engine: multi-order Vold–Kalman filter (VKF) order tracking (the public API is
:mod:`app.analysis.vkf`, which re-exports it).

The VKF (Hoelzl et al., paper Eqs. 1–20) models a measured signal as a sum of
``s`` orders with slowly varying complex envelopes,

    y[k] = Σ_n A_n[k] · exp(j φ_n[k]) + η[k],   φ_n[k] = 2π Σ_{l≤k} f_n[l] / fs,

and finds all envelopes *jointly* by minimising
``Σ_k |η[k]|² + Σ_n Σ_k r_n[k]² |∇^q A_n[k]|²``, i.e. by solving
``[Cᴴ C + (R S)ᵀ (R S)] a = Cᴴ y``. Solving the orders together is what
separates close orders (the sleeper passage sits 0.18 wheel orders from
wheel order 5).

How it is solved (see docs/vkf.md):

* the signal is mixed to complex baseband and decimated when the sample rate
  is far above the tracked band (``decimation="auto"``), which makes the
  problem both small and well conditioned;
* the coupled normal equations are factored as one banded Hermitian matrix
  (time-major unknowns, ``q·s`` sub-diagonals) and solved for all channels;
  iterative refinement with a residual computed from the structure removes
  the rounding bias of narrow bandwidths;
* long signals are cut into chunks whose overlap follows from the filter's
  own impulse response and which are joined with a raised-cosine crossfade.

Public API (documented with an example in docs/vkf.md)
-----------------------------------------------------
vkf, vkf_stream, vkf_overlap, VKFResult, VKFWarning. Order tracks of
railway data (``OrderTrack``, ``wheel_orders``, ``sleeper_passage``) live
in :mod:`app.analysis.orders`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from app.analysis.chunking import Chunk, plan_chunk_layout

from ._banded import solve_orders
from ._baseband import (
    BasebandPlan,
    EnvelopeSpline,
    filter_gain,
    guard_band,
    mixing_phase,
    plan_baseband,
    to_baseband,
)
from ._input import InputStats, VKFInput, check_mode, extremes_over, prepare_input, scan_input
from ._stationary import solve_with_stationary
from ._weights import bandwidth_from_weight, impulse_length, weight_squared

__all__ = [
    "vkf",
    "vkf_stream",
    "vkf_overlap",
    "VKFResult",
    "VKFWarning",
    "CLOSE_ORDERS_MESSAGE",
]

_EPS = np.finfo(np.float64).eps
#: signals up to this long (s) are solved in one piece by default
_SINGLE_SOLVE_S = 90.0
#: default chunk core length for longer signals, s
_AUTO_CHUNK_S = 60.0
#: relative level at which the impulse response tail is cut for the overlap
_OVERLAP_TOL = 1e-8
#: refinement that ends above this relative correction did not converge
_CONVERGED = 1e-8
#: grid on which the orders' guard band is evaluated, s
_GUARD_GRID_S = 1e-3


#: the start of the :class:`VKFWarning` issued when orders come closer than their bandwidth (a
#: ``warnings.filterwarnings`` message pattern: callers for whom that is by design filter it by it)
CLOSE_ORDERS_MESSAGE = r"orders \[.*\] come closer than their bandwidth"


class VKFWarning(UserWarning):
    """Issued when orders come closer than their bandwidth, or when a solve is
    ill-conditioned (a bandwidth narrower than double precision can resolve
    at the solve rate was widened, or refinement did not converge)."""


# --------------------------------------------------------------------------
# chunk planning
# --------------------------------------------------------------------------


@dataclass
class _Segment:
    """One solved chunk: its layout, envelope spline and solve information."""

    chunk: Chunk
    spline: EnvelopeSpline | None = None
    info: dict[str, Any] = field(default_factory=dict)

    lo = property(lambda self: self.chunk.lo)
    hi = property(lambda self: self.chunk.hi)
    out_lo = property(lambda self: self.chunk.out_lo)
    out_hi = property(lambda self: self.chunk.out_hi)

    def weight(self, index: np.ndarray) -> np.ndarray:
        """Crossfade weight at global sample indices."""
        return self.chunk.weight(index)


def _padding(inp: VKFInput, stats: InputStats, a: int, b: int, decimation: str | int) -> int:
    """Input samples of overlap a segment [a, b) needs on each side."""
    f_lo, f_hi, bw_min, bw_max = stats.over(a, b)
    return vkf_overlap(inp.fs, f_lo, f_hi, bw_min, bw_max, inp.q, decimation)


def _plan_segments(
    inp: VKFInput, stats: InputStats, chunk_duration: float | None, decimation: str | int
) -> list[_Segment]:
    n, fs = inp.n, inp.fs
    if chunk_duration is None:
        core = n if n <= _SINGLE_SOLVE_S * fs else int(round(_AUTO_CHUNK_S * fs))
    else:
        core = n if math.isinf(chunk_duration) else max(int(round(chunk_duration * fs)), 1)
    chunks = plan_chunk_layout(n, core, lambda a, b: _padding(inp, stats, a, b, decimation))
    return [_Segment(chunk) for chunk in chunks]


# --------------------------------------------------------------------------
# solving one segment
# --------------------------------------------------------------------------


def _filtered_inside(plan: BasebandPlan, length: int, idx: np.ndarray) -> np.ndarray:
    """Decimated samples whose anti-alias filter window lies inside the segment.

    Within ``plan.delay`` input samples of a segment end the FIR reads zeros
    beyond it and biases the baseband samples low. Those samples are left out
    of the data equation; their envelopes follow from the structural equation,
    which for a steady component extrapolates it exactly. Keeps at least half
    of the samples.
    """
    inside = (idx >= plan.delay) & (idx < length - plan.delay)
    if np.count_nonzero(inside) < idx.size // 2:
        return np.ones(idx.size, dtype=bool)
    return inside


def _close_pairs(f: np.ndarray, bw: np.ndarray) -> set[tuple[int, int]]:
    """Order pairs whose frequencies come closer than their mean bandwidth."""
    pairs = set()
    s = f.shape[0]
    for i in range(s - 1):
        gap = np.abs(f[i + 1 :] - f[i])
        limit = 0.5 * (bw[i + 1 :] + bw[i])
        hit = np.any(gap < limit, axis=1)
        pairs.update((i, i + 1 + int(j)) for j in np.flatnonzero(hit))
    return pairs


def _image_carriers(
    plan: BasebandPlan | None, phi: np.ndarray, f: np.ndarray, bw: np.ndarray, index: np.ndarray, fs: float
) -> np.ndarray:
    """Carriers of the orders' mirror images in the solved samples, ``g·exp(−j(φ + φ_c))``.

    A real signal holds every order ``A·exp(jφ)`` together with its image
    ``conj(A)·exp(−jφ)``. After mixing by ``f_c`` and the anti-alias FIR the
    image sits at ``−(f + f_c)`` with the FIR's gain there. Where an order is
    slower than its bandwidth (``valid`` False) it cannot be told from its own
    image: the image term is faded out between ``f = B`` and ``f = B/2``, so
    the refinement stays a contraction there (those samples are NaN anyway).

    Parameters
    ----------
    plan : BasebandPlan or None
        The segment's decimation (None: a full-rate solve).
    phi : ndarray, shape (s, m)
        Order phases at the solved samples (before mixing), rad.
    f, bw : ndarray, shape (s, m)
        Order frequencies and bandwidths there, Hz.
    index : ndarray, shape (m,)
        Global input sample indices of the solved samples.
    fs : float
        Input sample rate, Hz.
    """
    fade = np.clip(2.0 * f / bw - 1.0, 0.0, 1.0)
    if plan is None:
        return fade * np.exp(-1j * phi)
    gain = filter_gain(plan, f + plan.center, fs)
    return (fade * gain) * np.exp(-1j * (phi + mixing_phase(plan, index, fs)[None, :]))


def _segment_guard_band(inp: VKFInput, lo: int, hi: int) -> tuple[float, float]:
    """:func:`guard_band` of a segment, evaluated every ``_GUARD_GRID_S`` (the exact
    frequency extremes are added by :func:`plan_baseband`; the guard itself is a margin)."""
    step = max(int(inp.fs * _GUARD_GRID_S), 1)
    grid = np.unique(np.append(np.arange(0, hi - lo, step), hi - lo - 1))
    return guard_band(inp.at("freqs", lo, hi, grid), inp.at("bandwidth", lo, hi, grid))


def _solve_segment(
    inp: VKFInput, seg: _Segment, cum_lo: np.ndarray, decimation: str | int, real_signal: bool = True,
    stationary: np.ndarray | None = None,
) -> set[tuple[int, int]]:
    """Solve one segment in place (sets ``seg.spline`` and ``seg.info``).

    ``cum_lo`` is Σ_{l<lo} f_n[l] (Hz·samples) for the global phase.
    """
    lo, hi, fs, q = seg.lo, seg.hi, inp.fs, inp.q
    f_lo, f_hi, _, bw_max = extremes_over(inp, lo, hi)  # exact, not block-rounded
    plan = plan_baseband(f_lo, f_hi, bw_max, fs, decimation, _segment_guard_band(inp, lo, hi))
    y = inp.y_slice(lo, hi)
    if plan is None:
        factor = 1
        idx = np.arange(hi - lo)
        ys = y
    else:
        factor = plan.factor
        idx = np.arange(0, hi - lo, factor)
        ys = to_baseband(y, lo, plan, fs)
    del y
    phi = inp.phase0[:, None] + (2.0 * np.pi / fs) * (cum_lo[:, None] + inp.cumsum_freqs(lo, hi, idx))
    f = inp.at("freqs", lo, hi, idx)
    bw = inp.at("bandwidth", lo, hi, idx)
    image = _image_carriers(plan, phi, f, bw, lo + idx, fs) if real_signal else None
    if plan is not None:
        phi -= mixing_phase(plan, lo + idx, fs)[None, :]
    rate = fs / factor
    r2 = weight_squared(bw[:, q:], rate, q)
    r2_max = 0.25 / (_EPS * 4.0**q)
    widened = bool(np.any(r2 > r2_max))
    if widened:
        np.minimum(r2, r2_max, out=r2)
    mask = None if plan is None else _filtered_inside(plan, hi - lo, idx)
    if stationary is None:
        sol = solve_orders(ys, phi, r2, q, mask, image)
    else:
        sol = solve_with_stationary(ys, phi, f, bw, r2, lambda b: np.minimum(weight_squared(b, rate, q), r2_max),
                                    q, mask, image, stationary)
    seg.spline = EnvelopeSpline(2.0 * sol.envelope, lo, factor)
    seg.info = {
        "decimation": factor,
        "solve_rate_hz": rate,
        "center_hz": None if plan is None else plan.center,
        "refinement_iterations": sol.iterations,
        "refinement_correction": sol.correction,
        "widened_min_bandwidth_hz": float(bandwidth_from_weight(r2_max, rate, q)) if widened else None,
        "images_dropped": sol.images_dropped,
        "stationary_orders": [] if stationary is None else [int(i) for i in np.flatnonzero(stationary)],
    }
    if sol.images_dropped:
        warnings.warn(
            f"the real-signal refinement did not converge for samples {lo}–{hi} (a record much shorter than "
            "its narrowest order filter's impulse response): the orders' mirror images were left in the "
            "noise (Eq. 20 as written)",
            VKFWarning,
            stacklevel=4,
        )
    if widened:
        warnings.warn(
            f"bandwidth below {seg.info['widened_min_bandwidth_hz']:.3g} Hz cannot be resolved in double "
            f"precision at a solve rate of {rate:g} Hz (filter_order={q}); it was widened to that value "
            f"for samples {lo}–{hi}. Use decimation='auto'.",
            VKFWarning,
            stacklevel=4,
        )
    if sol.correction > _CONVERGED:
        warnings.warn(
            f"VKF refinement did not converge (relative correction {sol.correction:.2g}) for samples "
            f"{lo}–{hi}: the problem is too ill-conditioned at this solve rate; use decimation='auto'.",
            VKFWarning,
            stacklevel=4,
        )
    return _close_pairs(f, bw)


def _iter_segments(
    inp: VKFInput, chunk_duration: float | None, decimation: str | int, real_signal: bool = True,
    stationary: np.ndarray | None = None,
) -> Iterator[tuple[int, list[_Segment], np.ndarray, set[tuple[int, int]]]]:
    """Solve the planned segments in order.

    Yields ``(i, segments, cum_lo, pairs)`` after segment ``i`` is solved,
    with ``cum_lo = Σ_{l<lo} f_n[l]`` of that segment.
    """
    stats = scan_input(inp)
    segments = _plan_segments(inp, stats, chunk_duration, decimation)
    cum = np.zeros(inp.s)
    pos = 0
    for i, seg in enumerate(segments):
        if seg.lo > pos:
            cum = cum + inp.sum_freqs(pos, seg.lo)
            pos = seg.lo
        pairs = _solve_segment(inp, seg, cum, decimation, real_signal, stationary)
        yield i, segments, cum.copy(), pairs


# --------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------


class VKFResult:
    """Envelopes and components of a VKF run over input samples [start, stop).

    Full-rate arrays are computed on first access and cached; use
    :meth:`envelope_at` for a reduced output rate without materialising them.
    Arrays have a leading channel axis when ``y`` was 2-D.

    Attributes
    ----------
    envelope : ndarray, complex, shape ([channels,] s, n)
        Complex envelope of every order, m/s² for ABA: ``2·A_n`` of the paper,
        so that ``waveform = Re(envelope · exp(j·phi))``. NaN where the order
        is not trackable (see ``valid``).
    amplitude : ndarray, shape ([channels,] s, n)
        Peak amplitude of each real component, ``|envelope|``.
    phase : ndarray, shape ([channels,] s, n)
        ``angle(envelope)``, rad, relative to ``phi``.
    waveform : ndarray, shape ([channels,] s, n)
        Real components ``x_n[k]``; 0 where not trackable.
    residual : ndarray, shape ([channels,] n)
        ``y − Σ_n waveform_n``.
    phi : ndarray, shape (s, n)
        Phases used, rad: ``phase0 + 2π Σ_{l≤k} f_n[l] / fs`` (paper Eq. 3).
    bandwidth : ndarray, shape (s, n)
        Requested full −3 dB bandwidth, Hz.
    valid : ndarray of bool, shape (s, n)
        False where an order's frequency is below its bandwidth (e.g. a
        standing train): the order then overlaps its own mirror image at
        −f and DC and cannot be separated.
    close_orders : list of (int, int)
        Pairs of orders that come closer than their mean bandwidth somewhere
        (their separation then rests on the coupled solve alone).
    info : dict
        Decimation, solve rate, refinement iterations per chunk.
    start, stop : int
        Input sample range of this result.
    fs : float
        Input sample rate, Hz.
    filter_order : int
        q.
    """

    def __init__(
        self,
        inp: VKFInput,
        segments: list[_Segment],
        start: int,
        stop: int,
        cum_start: np.ndarray,
        close_orders: list[tuple[int, int]],
    ) -> None:
        self._inp = inp
        self._segments = segments
        self.start = int(start)
        self.stop = int(stop)
        self._cum_start = cum_start
        self.close_orders = close_orders
        self.fs = inp.fs
        self.filter_order = inp.q
        self.info = {"chunks": [dict(lo=s.lo, hi=s.hi, **s.info) for s in segments]}

    def __len__(self) -> int:
        return self.stop - self.start

    def __repr__(self) -> str:
        return (
            f"VKFResult(samples {self.start}–{self.stop}, orders={self._inp.s}, channels={self._inp.channels}, "
            f"fs={self.fs:g} Hz, filter_order={self.filter_order}, chunks={len(self._segments)})"
        )

    def _squeeze(self, a: np.ndarray) -> np.ndarray:
        return a[0] if self._inp.y_is_1d else a

    def _raw_envelope(self, index: np.ndarray) -> np.ndarray:
        """Crossfaded envelopes (channels, s, len(index)) at global indices."""
        out = np.zeros((self._inp.channels, self._inp.s, index.size), dtype=np.complex128)
        for seg in self._segments:
            sel = np.flatnonzero((index >= seg.out_lo) & (index < seg.out_hi))
            if sel.size == 0:
                continue
            k = index[sel]
            w = seg.weight(k)
            if np.all(w == 1.0):
                out[..., sel] = seg.spline(k)
            else:
                out[..., sel] += seg.spline(k) * w
        return out

    def _valid_at(self, index: np.ndarray) -> np.ndarray:
        if index.size == 0:
            return np.ones((self._inp.s, 0), dtype=bool)
        lo, hi = int(index.min()), int(index.max()) + 1
        local = index - lo
        return self._inp.at("freqs", lo, hi, local) >= self._inp.at("bandwidth", lo, hi, local)

    def _masked(self, env: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Raw envelopes (channels, s, m) set to NaN where ``valid`` (s, m) is False, in place."""
        env[:, ~valid] = np.nan
        return self._squeeze(env)

    def envelope_at(self, index: Any) -> np.ndarray:
        """Envelopes at sample indices relative to ``start`` (e.g. a reduced rate).

        Parameters
        ----------
        index : array_like of int
            Sample indices in ``[0, len(self))``, e.g. ``np.arange(0, len(res), 24)``
            for a 1 kHz output from 24 kHz input.

        Returns
        -------
        ndarray, complex, shape ([channels,] s, len(index))
            NaN where the order is not trackable.
        """
        index = np.asarray(index, dtype=np.int64).reshape(-1)
        if index.size and (index.min() < 0 or index.max() >= len(self)):
            raise ValueError(f"index must lie in [0, {len(self)}), got {index.min()}..{index.max()}")
        g = index + self.start
        return self._masked(self._raw_envelope(g), self._valid_at(g))

    @cached_property
    def valid(self) -> np.ndarray:
        return self._valid_at(np.arange(self.start, self.stop))

    @cached_property
    def envelope(self) -> np.ndarray:
        return self._masked(self._raw_envelope(np.arange(self.start, self.stop)), self.valid)

    @cached_property
    def phi(self) -> np.ndarray:
        cs = self._inp.cumsum_freqs(self.start, self.stop)
        cs += self._cum_start[:, None]
        return self._inp.phase0[:, None] + (2.0 * np.pi / self.fs) * cs

    @cached_property
    def waveform(self) -> np.ndarray:
        wave = (self.envelope * np.exp(1j * self.phi)).real
        wave[..., ~self.valid] = 0.0
        return wave

    @cached_property
    def amplitude(self) -> np.ndarray:
        return np.abs(self.envelope)

    @cached_property
    def phase(self) -> np.ndarray:
        return np.angle(self.envelope)

    @cached_property
    def bandwidth(self) -> np.ndarray:
        return np.array(self._inp.bw_slice(self.start, self.stop))

    @cached_property
    def residual(self) -> np.ndarray:
        y = self._inp.y_slice(self.start, self.stop)
        wave = self.waveform if not self._inp.y_is_1d else self.waveform[None]
        return self._squeeze(y - wave.sum(axis=-2))


def _check_stationary(stationary: Any, s: int) -> np.ndarray | None:
    """Validate the ``stationary`` keyword: None, or one boolean per order, not all True.

    Returns None when no order is stationary."""
    if stationary is None:
        return None
    stat = np.asarray(stationary)
    if stat.shape != (s,) or stat.dtype != bool:
        raise ValueError(f"stationary must be None or {s} booleans (one per order), got {stat.dtype} {stat.shape}")
    if stat.all():
        raise ValueError("stationary must leave at least one order that is not stationary")
    return stat if stat.any() else None


def _warn_close(pairs: set[tuple[int, int]]) -> list[tuple[int, int]]:
    close = sorted(pairs)
    if close:
        warnings.warn(
            f"orders {close} come closer than their bandwidth; their separation rests on the coupled solve",
            VKFWarning,
            stacklevel=3,
        )
    return close


def vkf_overlap(fs: float, f_min: float, f_max: float, bw_min: float, bw_max: float, filter_order: int = 2,
                decimation: str | int = "auto", tol: float = _OVERLAP_TOL) -> int:
    """Input samples of overlap a chunk needs on each side for exact joining.

    Parameters
    ----------
    fs : float
        Sample rate, Hz.
    f_min, f_max : float
        Range of the tracked frequencies over the chunk and its surroundings, Hz.
    bw_min, bw_max : float
        Range of the bandwidths, Hz (> 0).
    filter_order : {1, 2, 3}
    decimation : {"auto", "off"} or int
    tol : float
        Neglected tail of the impulse response, relative (default 1e-8, what
        :func:`vkf` itself uses). The overlap grows like ``ln(1/tol)``.

    Returns
    -------
    int
        Overlap in samples: the impulse-response length of the narrowest
        filter (tail below ``tol``) plus the anti-alias filter's half length.
        Chunks solved over ``[start - overlap, stop + overlap)`` agree with
        the unchunked solution to ~``tol`` of the signal level inside
        ``[start, stop)``.
    """
    if not 0.0 < tol < 1.0:
        raise ValueError(f"tol must lie in (0, 1), got {tol!r}")
    decimation, _ = check_mode(decimation, None)
    if filter_order not in (1, 2, 3):
        raise ValueError(f"filter_order must be 1, 2 or 3, got {filter_order!r}")
    if not (0 < bw_min <= bw_max):
        raise ValueError(f"bandwidth range must satisfy 0 < bw_min <= bw_max, got {bw_min}, {bw_max}")
    # the narrowest pass band a solve over this range can get (every order guarded by
    # at least bw_min): the longest anti-alias filter, an upper bound of the delay
    narrowest = guard_band(np.array([[f_min], [f_max]]), np.full((2, 1), bw_min))
    plan = plan_baseband(f_min, f_max, bw_max, fs, decimation, narrowest)
    factor = 1 if plan is None else plan.factor
    delay = 0 if plan is None else plan.delay
    return impulse_length(bw_min, fs / factor, filter_order, tol) * factor + delay + factor


def vkf(
    y: Any,
    fs: float,
    freqs: Any,
    bandwidth: Any,
    filter_order: int = 2,
    *,
    decimation: str | int = "auto",
    chunk_duration: float | None = None,
    phase0: Any = None,
    real_signal: bool = True,
    stationary: Any = None,
) -> VKFResult:
    """Extract orders with the multi-order Vold–Kalman filter.

    Parameters
    ----------
    y : array_like, shape (N,) or (channels, N)
        Real signal, e.g. axle-box acceleration in m/s². Channels share the
        orders: the system is factored once and solved for all of them.
        ndarrays, ``np.memmap`` and h5py datasets are read chunk by chunk.
    fs : float
        Sample rate, Hz.
    freqs : array_like, shape (s, N) or (s,)
        Instantaneous frequency of each order, Hz, in ``[0, fs/2)``; a (s,)
        array means constant frequencies. May be an
        :class:`~app.analysis.orders.OrderTrack` (lazy ``multiplier × speed``).
    bandwidth : float or array_like, shape (s,) or (s, N)
        Full −3 dB (half-power) bandwidth of each order's filter, Hz, > 0.
        An (s, N) array lets it follow the speed (constant in orders).
    filter_order : {1, 2, 3}
        Order q of the difference operator of the structural equation.
        Higher q gives a flatter pass band and steeper roll-off (and longer
        impulse response).
    decimation : {"auto", "off"} or int, optional
        ``"auto"`` (default) mixes to complex baseband and decimates when the
        sample rate is at least 4x what the tracked band needs; results are
        returned at the input rate. ``"off"`` solves Eq. 20 at the input rate
        exactly. An int forces that factor.
    chunk_duration : float, optional
        Core length of a chunk, s. None (default): one solve up to 90 s,
        60 s chunks beyond. ``math.inf``: always one solve.
    phase0 : array_like, shape (s,), optional
        Phase of each order before the first sample, rad (default 0).
    real_signal : bool, optional
        True (default): ``y`` is real, so every order also appears as its
        mirror image at ``−f``; the solve models the images (the real-signal
        form of Eq. 20, see the notes) instead of leaving them in the noise.
        False: Eq. 20 as the paper writes it. The two agree where every
        order's filter rejects the images (narrow, equal bandwidths); next to
        narrow orders a wide one is off by ~1 % inside a record and up to
        25 % at its ends with False.
    stationary : array_like of bool, shape (s,), optional
        Orders whose envelope is a function of their own frequency only (a
        source that does not change along the record, such as a wheel's
        out-of-roundness: its response moves with the speed, not with time).
        Each segment is then solved in three steps: every order at the
        stationary orders' (narrow) bandwidth; the stationary envelopes
        replaced by a local-linear fit over log-frequency (Gaussian kernel,
        1 % of the frequency); the orders wider than them solved again at
        their own bandwidths on what is left. A wide order whose band holds
        a stationary one then keeps its changes instead of losing the part
        at the stationary order's line (docs/vkf.md, *Stationary orders*).
        Chunks fit their stationary orders each on their own stretch.
        Default None: every order is solved jointly at its own bandwidth.

    Returns
    -------
    VKFResult

    Raises
    ------
    ValueError
        If an argument is invalid; the message names it.

    Warns
    -----
    VKFWarning
        If orders come closer than their bandwidth, or a solve is
        ill-conditioned (only possible with ``decimation="off"`` or a fixed
        factor).

    Notes
    -----
    The bandwidth sets the weights ``r = sqrt(√2 − 1) / (2 sin(π B / (2 f_r)))^q``
    at the solve rate ``f_r``, which puts the stationary response
    ``1 / (1 + r² (2 sin(ω/2))^(2q))`` at −3 dB ``B/2`` Hz either side of the
    tracked frequency.

    With ``real_signal`` the envelopes minimise
    ``Σ_k (y_k − Σ_n Re(2 A_n e^{jφ_n}))² + 2 Σ_n Σ_i r_n² |(S_q A_n)_i|²``: the
    normal equations gain the term ``Cᴴ conj(C A)`` (the images), which the
    engine's iterative refinement carries (the banded factor of Eq. 20 stays
    the preconditioner). Where an order is slower than its bandwidth it is
    not told from its own image (``valid`` is False there): the image term is
    faded out between ``f = B`` and ``f = B/2``.

    Examples
    --------
    >>> import numpy as np
    >>> from app.analysis.vkf import vkf
    >>> fs = 2000.0
    >>> t = np.arange(4000) / fs
    >>> y = 2.0 * np.cos(2 * np.pi * 100.0 * t + 0.3)
    >>> res = vkf(y, fs, [100.0], bandwidth=5.0)
    >>> bool(abs(res.amplitude[0, 2000] - 2.0) < 1e-6)
    True
    """
    decimation, chunk_duration = check_mode(decimation, chunk_duration)
    inp = prepare_input(y, fs, freqs, bandwidth, filter_order, phase0)
    stat = _check_stationary(stationary, inp.s)
    pairs: set[tuple[int, int]] = set()
    segments: list[_Segment] = []
    for _, segments, _, seg_pairs in _iter_segments(inp, chunk_duration, decimation, real_signal, stat):  # noqa: B007
        pairs |= seg_pairs
    return VKFResult(inp, segments, 0, inp.n, np.zeros(inp.s), _warn_close(pairs))


def vkf_stream(
    y: Any,
    fs: float,
    freqs: Any,
    bandwidth: Any,
    filter_order: int = 2,
    *,
    decimation: str | int = "auto",
    chunk_duration: float | None = None,
    phase0: Any = None,
    real_signal: bool = True,
    stationary: Any = None,
) -> Iterator[VKFResult]:
    """Run :func:`vkf` chunk by chunk with bounded memory.

    Same parameters as :func:`vkf`. Yields one :class:`VKFResult` per chunk
    with the final, crossfaded results for consecutive input ranges
    ``[block.start, block.stop)`` that cover the input exactly once, in
    order; concatenated along the last axis they equal what :func:`vkf`
    returns with the same ``chunk_duration``. Only the current and the
    previous chunk are held in memory (as long as the caller lets go of
    the blocks it has consumed), so inputs of any length (``np.memmap``,
    h5py datasets) can be processed. Values are checked in a first pass
    before anything is yielded.

    Yields
    ------
    VKFResult
        Results over input samples ``[block.start, block.stop)``. Its
        ``close_orders`` are the pairs that come closer than their bandwidth
        in this chunk; a :class:`VKFWarning` is issued when a pair is first
        found.

    Examples
    --------
    Amplitudes at every 24th sample, written into a preallocated array
    (an ``np.memmap`` for records larger than memory)::

        step = 24
        out = np.empty((n_orders, -(-n_samples // step)))
        for block in vkf_stream(y, fs, freqs, bandwidth):
            k = np.arange(-(-block.start // step) * step, block.stop, step)
            out[:, k // step] = np.abs(block.envelope_at(k - block.start))
    """
    decimation, chunk_duration = check_mode(decimation, chunk_duration)
    inp = prepare_input(y, fs, freqs, bandwidth, filter_order, phase0)
    stat = _check_stationary(stationary, inp.s)
    seen: set[tuple[int, int]] = set()
    for i, segments, cum_lo, pairs in _iter_segments(inp, chunk_duration, decimation, real_signal, stat):
        seg = segments[i]
        start = 0 if i == 0 else seg.out_lo
        stop = segments[i + 1].out_lo if i + 1 < len(segments) else inp.n
        start_cum = cum_lo + inp.sum_freqs(seg.lo, start)
        new = pairs - seen
        seen |= pairs
        close = _warn_close(new) if new else []
        yield VKFResult(inp, segments[max(i - 1, 0) : i + 1], start, stop, start_cum, sorted(pairs) or close)
        if i > 0:
            segments[i - 1] = None  # type: ignore[call-overload]  # only the yielded block keeps it
