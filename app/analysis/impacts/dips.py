"""Isolated dips in an estimated running surface: a bank of matched filters.

A dipped weld, a dipped joint and a wheel flat are all, seen from the
contact, a short dip of the surface, roughly ``-d/2 (1 + cos(2 pi u / L))``
over ``|u| < L/2``. The background they sit in is the surface's own random
roughness (a red spectrum, Sato's ``A / Omega³``) and the measurement noise
carried back through the dynamics. The best linear estimate of the depth of
a dip of known shape in Gaussian coloured background is the generalised
least squares one,

    d(x) = <t_L(. - x), P^-1 r> / <t_L, P^-1 t_L>

(``P`` the background's power spectrum): a matched filter after whitening.
:func:`find_dips` estimates ``P`` from the surface itself (Welch, then a
running low percentile across wavenumbers: isolated dips hardly move it, and
the comb of lines of a wheel flat — a dip every revolution — is not taken for
background), runs the filter for each length of
:data:`DIP_LENGTHS_M`, divides each output by its robust spread (1.4826 ×
median absolute deviation, per stretch of :data:`SCALE_BLOCK_M`) and keeps
the local maxima where the best length's score reaches ``threshold`` and the
depth :data:`MIN_DEPTH_M`: its position, length, depth (m) and score. These
are candidates; which of them are impacts is decided across the wheels
(:mod:`app.analysis.impacts.classify`).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from app.analysis.impacts.surface import SurfaceEstimate
from app.analysis.robust import mad_sd

__all__ = ["DIP_LENGTHS_M", "WELD_LENGTHS_M", "DETECTION_THRESHOLD", "MIN_DEPTH_M", "SCALE_BLOCK_M", "LONG_SCALE_BLOCK_M",
           "TRACE_STEP_M", "Dips", "DipTrace", "find_dips", "scan_dips"]

#: Lengths of the matched dips, m (a flat's few cm … a weld's metre and more).
DIP_LENGTHS_M: tuple[float, ...] = (0.04, 0.1, 0.25, 0.5, 1.0, 1.6)
#: Lengths of the weld filters whose scores are kept as a trace (:class:`DipTrace`) and combined across
#: the wheels, m: the welds' 0.5–2 m in steps of about sqrt 2 (a weld between two lengths loses a few
#: per cent of its score; the 0.25 m filter, with the most independent values per km, is left out).
WELD_LENGTHS_M: tuple[float, ...] = (0.5, 0.7, 1.0, 1.4, 2.0)
#: Score (depth over its robust spread) a dip must reach to be kept as a candidate.
DETECTION_THRESHOLD = 3.5
#: Shallower dips are not kept whatever their score (the short-wave roughness is tiny), m.
MIN_DEPTH_M = 0.1e-3
#: Stretch over which the spread of the short filters' output is taken, m.
SCALE_BLOCK_M = 40.0
#: The same for the long (weld) filters, m: their output is correlated over a metre, so 40 m hold
#: only ~40 independent values and their MAD scatters by ~±18 %; 160 m hold ~160 (±9 %). Their spread
#: is the larger of the two (a change of track type or rail inside a long block would otherwise leave
#: its rougher side under-scaled for up to a block, reading as a row of dips).
LONG_SCALE_BLOCK_M = 160.0
#: Spacing of the long filters' score trace (:class:`DipTrace`), m of travelled distance (2 coarse cells;
#: the shortest long filter's peak, 0.25 m, loses < 3 % between two samples).
TRACE_STEP_M = 0.08
#: No dips are sought this close to the ends of a valid stretch (the filters are truncated there), m.
EDGE_M = 6.0
#: Sato's short-wave rail roughness of "good rail", ``S(Omega) = A / Omega³`` (one-sided, m² per rad/m), A in
#: m² rad² / m: the value the vehicle–track literature quotes (e.g. Zhai) and the physics runs use.
SATO_A_GOOD_RAIL = 4.15e-8
#: The background spectrum is at least this share of good rail's (a rail ten times smoother in amplitude than
#: good rail; ground rail in the simulator is 0.3×). A record without roughness (the physics' smooth track,
#: a short stretch of fresh rail) has no background of its own: its spectrum is then the dips' themselves
#: and the residual of the inversion, the whitened filters weigh the estimate where that spectrum has its
#: nulls, and depths read low and erratic (physics, smooth 100 MN/m at 30 m/s: a 0.6 m, 0.2 mm weld read
#: 0.088 mm and was dropped below :data:`MIN_DEPTH_M`; with the floor 0.25, a 1 m, 0.3 mm weld 0.30). On any
#: rough rail the floor is far below the background and changes nothing.
BACKGROUND_FLOOR = 0.01
#: Bins and percentile of the running filter across the background spectrum (0.05 1/m a bin).
_PSD_FILTER_BINS = 31
_PSD_PERCENTILE = 20
#: A dip within this of one scoring SIDE_LOBE_RATIO times more is its side lobe, m.
SIDE_LOBE_M = 3.0
SIDE_LOBE_RATIO = 2.0
#: Length of the background spectrum's Welch segments, m.
_WELCH_M = 20.48
#: Dips this long or longer are sought on a grid _COARSE times coarser, m.
_COARSE_FROM_M = 0.2
_COARSE = 4


@dataclass(frozen=True)
class Dips:
    """Dips found in one wheel's surface (one entry each, ascending position).

    Attributes
    ----------
    s_m : numpy.ndarray
        Travelled distance of the dip's centre, m.
    length_m : numpy.ndarray
        Length of the matched dip that scored best, m.
    depth_m : numpy.ndarray
        Its depth, m (> 0).
    score : numpy.ndarray
        Depth over the filter's robust spread there.
    speed_mps : numpy.ndarray
        Speed there, m/s.
    """

    s_m: np.ndarray
    length_m: np.ndarray
    depth_m: np.ndarray
    score: np.ndarray
    speed_mps: np.ndarray

    def __len__(self) -> int:
        return int(self.s_m.size)

    @classmethod
    def empty(cls) -> Dips:
        """No dips."""
        z = np.zeros(0)
        return cls(z, z, z, z, z)


@dataclass(frozen=True)
class DipTrace:
    """The long (weld) filters' scores along one wheel's travel, sampled every :data:`TRACE_STEP_M`, per length.

    Samples, not maxima over the stretch: a maximum per wheel would raise the roughness's scores (each
    rail its own maximum) more than a weld's (one position for all). NaN where no dip is sought
    (invalid cells, the ends of a valid stretch). Combined, length by length, across the wheels at
    one track position by :func:`app.analysis.impacts.welds.combined_track_dips`.

    Attributes
    ----------
    s_m : numpy.ndarray
        Travelled distance of the stretch's centre, m, shape (m,).
    lengths_m : numpy.ndarray
        The filters' dip lengths, m, shape (k,).
    score : numpy.ndarray
        Depth over its robust spread, shape (k, m).
    depth_m : numpy.ndarray
        Depth, m, shape (k, m).
    """

    s_m: np.ndarray
    lengths_m: np.ndarray
    score: np.ndarray
    depth_m: np.ndarray

    def __len__(self) -> int:
        return int(self.s_m.size)

    @classmethod
    def empty(cls) -> DipTrace:
        """No trace."""
        z = np.zeros(0)
        return cls(z, z, np.zeros((0, 0)), np.zeros((0, 0)))


def _template(length_m: float, step: float) -> np.ndarray:
    half = int(math.ceil(0.5 * length_m / step))
    u = np.arange(-half, half + 1) * step / length_m
    return np.where(np.abs(u) < 0.5, -0.5 * (1.0 + np.cos(2 * np.pi * u)), 0.0)


def _background_psd(h: np.ndarray, valid: np.ndarray, step: float, nperseg: int,
                    est: SurfaceEstimate, tilt: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Welch spectrum of the valid stretches (one-sided, per 1/m), a smooth background of it.

    A running low percentile across wavenumbers, over the bins the estimate
    kept (in its band, off its notches): the background is smooth, a wheel
    flat's comb of lines (every 1 / circumference, each a few bins wide) is
    not. A constant factor on it changes neither a depth nor a score. With
    ``tilt`` (the weld trace) the percentile is taken of ``P kappa³``, the spectrum with rail roughness's own
    slope taken out (Sato's ``A / Omega³``), where the background is about flat:
    of ``P`` itself, a window of 1.5 1/m on a slope of ``kappa⁻³`` would take its
    low values from the window's short-wave end and put the background at long
    waves an order of magnitude too low, over-weighting them (the long filters
    then lose a quarter of a weld's score).
    """
    # here: scipy.signal imports scipy.stats (≈ 1 s), which the API, reading this package, does not need
    from scipy.signal import welch

    x = np.where(valid, h, 0.0)
    frac = float(valid.mean()) if valid.size else 0.0
    nper = min(nperseg, 1 << int(math.floor(math.log2(max(x.size, 16)))))
    k, p = welch(x, fs=1.0 / step, nperseg=nper, detrend=False)
    tilt_k = np.maximum(k, k[1] if k.size > 1 else 1.0) ** 3 if tilt else np.ones(k.size)
    p = p * tilt_k
    kept = est.gain(k) > 0.5
    idx = np.flatnonzero(kept)
    if idx.size == 0:
        return k, np.maximum(p / tilt_k / max(frac, 1e-3), _roughness_floor(k))
    half = _PSD_FILTER_BINS // 2
    padded = np.concatenate([np.full(half, np.nan), np.where(kept, p, np.nan), np.full(half, np.nan)])
    windows = np.sort(np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1)[idx], axis=1)  # NaN last
    count = np.sum(np.isfinite(windows), axis=1)
    pos = (count - 1) * (_PSD_PERCENTILE / 100.0)
    lo_i = np.floor(pos).astype(np.int64)
    hi_i = np.minimum(lo_i + 1, count - 1)
    frac_i = pos - lo_i
    rows = np.arange(windows.shape[0])
    filtered = windows[rows, lo_i] * (1.0 - frac_i) + windows[rows, hi_i] * frac_i
    # outside what the estimate kept: the nearest kept value (the weights are ~0 there)
    out = np.interp(np.arange(p.size), idx, filtered) / tilt_k / max(frac, 1e-3)  # the invalid cells diluted it
    return k, np.maximum(out, _roughness_floor(k))


def _roughness_floor(k: np.ndarray) -> np.ndarray:
    """:data:`BACKGROUND_FLOOR` × good rail's roughness spectrum at wavenumbers ``k`` (1/m), one-sided per 1/m
    (``P(k) = 2 pi S(2 pi k) = A / (4 pi² k³)``; below the first bin held at it)."""
    kk = np.maximum(k, k[1] if k.size > 1 else 1.0)
    return BACKGROUND_FLOOR * SATO_A_GOOD_RAIL / (4.0 * np.pi**2 * kk**3)


def _robust_scale(x: np.ndarray, valid: np.ndarray, block: int) -> np.ndarray:
    """1.4826 × MAD of ``x`` per block of cells (over its valid cells, every fourth one), per cell."""
    sub = 4
    xs = np.where(valid, x, np.nan)[::sub]
    per = max(block // sub, 8)
    nb = -(-xs.size // per)
    grid = np.full(nb * per, np.nan)
    grid[: xs.size] = xs
    grid = grid.reshape(nb, per)
    enough = np.sum(np.isfinite(grid), axis=1) >= 32
    if nb > 1 and not enough[-1]:  # a short last block joins the one before
        enough[-1] = False
    out = np.full(x.size, np.nan)
    if not enough.any():
        return out
    mad = mad_sd(grid[enough], axis=1)
    # constant within a block; a block without enough valid cells takes its nearest good block's
    blocks = np.minimum(np.arange(x.size) // (per * sub), nb - 1)
    good = np.flatnonzero(enough)
    nearest = good[np.clip(np.searchsorted(good, blocks), 0, good.size - 1)]
    left = good[np.clip(np.searchsorted(good, blocks, side="right") - 1, 0, good.size - 1)]
    pick = np.where(np.abs(nearest - blocks) <= np.abs(left - blocks), nearest, left)
    return mad[np.searchsorted(good, pick)]


def _bank(h: np.ndarray, valid: np.ndarray, step: float, est: SurfaceEstimate,
          lengths: tuple[float, ...], scale_block_m: float = SCALE_BLOCK_M,
          per_length: list[tuple[np.ndarray, np.ndarray]] | None = None,
          tilt: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Best score, its length and its depth per cell over a bank of matched dips on one grid.

    With ``per_length`` (a list) each length's (score, depth) per cell is appended to it; ``tilt``:
    see :func:`_background_psd`. The spread is per block of ``scale_block_m`` and, where that is
    longer, the larger of it and the one per :data:`SCALE_BLOCK_M`.
    """
    n = h.size
    k_bg, p_bg = _background_psd(h, valid, step, max(256, int(_WELCH_M / step)), est, tilt)
    nfft = 1 << int(math.ceil(math.log2(n + int(max(lengths) / step) + 8)))
    kappa = np.fft.rfftfreq(nfft, step)
    gain = est.gain(kappa)
    psd = np.interp(kappa, k_bg, p_bg)
    # the surface is G (d t + b), G what the estimate kept: numerator weight G / P, denominator G² / P
    inband = (gain > 0.05) & (kappa > 0)
    floor = 1e-9 * float(psd[inband].max()) if inband.any() else 1.0
    held = np.maximum(psd, floor)
    # only where the estimate kept the surface and the spectrum is positive (a zero spectrum: no weight, not inf)
    num_w = np.divide(gain, held, out=np.zeros_like(held), where=inband & (held > 0))
    den_w = num_w * gain
    r = np.fft.rfft(np.where(valid, h, 0.0), nfft)
    blocks = sorted({max(int(SCALE_BLOCK_M / step), 256), max(int(scale_block_m / step), 256)})
    best = np.full(n, -np.inf)
    best_l = np.zeros(n)
    best_d = np.zeros(n)
    for length in lengths:
        t = _template(float(length), step)
        tt = np.zeros(nfft)
        half = t.size // 2
        tt[: half + 1] = t[half:]
        tt[nfft - half :] = t[:half]  # centred on cell 0 (circular)
        tf = np.fft.rfft(tt)
        den = float(np.fft.irfft(np.abs(tf) ** 2 * den_w, nfft)[0])
        if not den > 0:
            continue
        depth = np.fft.irfft(r * np.conj(tf) * num_w, nfft)[:n] / den
        scale = _robust_scale(depth, valid, blocks[0])
        for block in blocks[1:]:
            scale = np.fmax(scale, _robust_scale(depth, valid, block))
        score = np.divide(depth, scale, out=np.full(n, -np.inf), where=valid & (scale > 0))
        if per_length is not None:
            per_length.append((score, depth))
        better = score > best
        best = np.where(better, score, best)
        best_l = np.where(better, float(length), best_l)
        best_d = np.where(better, depth, best_d)
    return best, best_l, best_d


def _covered(start: np.ndarray, stop: np.ndarray, n: int) -> np.ndarray:
    """Cells of ``[0, n)`` inside any of the intervals ``[start_i, stop_i)`` (clipped to the array).

    One pass over the cells whatever the number of intervals (a valid mask broken in many places
    has hundreds of thousands of ends).
    """
    lo = np.clip(start, 0, n)
    hi = np.clip(stop, 0, n)
    keep = lo < hi
    edges = np.bincount(lo[keep], minlength=n + 1) - np.bincount(hi[keep], minlength=n + 1)
    return np.cumsum(edges[:n]) > 0


def _without_side_lobes(peaks: np.ndarray, score: np.ndarray, step: float) -> np.ndarray:
    """Peaks less those within :data:`SIDE_LOBE_M` of one scoring :data:`SIDE_LOBE_RATIO` times more.

    The whitened, band-limited filters answer an isolated dip with side lobes a
    metre or two either side; a wheel flat's hits (one circumference apart)
    score alike and all stay.
    """
    if peaks.size < 2:
        return peaks
    order = peaks[np.argsort(-score[peaks], kind="stable")]
    reach = SIDE_LOBE_M / step
    kept: list[int] = []  # by position: the peaks within reach of one are a slice (bisect), not a scan of all
    kept_score: list[float] = []
    for p, sp in zip(order.tolist(), score[order].tolist(), strict=True):
        i, j = bisect.bisect_left(kept, p - reach), bisect.bisect_right(kept, p + reach)
        if any(sk >= SIDE_LOBE_RATIO * sp for sk in kept_score[i:j]):
            continue
        at = bisect.bisect_left(kept, p)
        kept.insert(at, p)
        kept_score.insert(at, sp)
    return np.array(kept, dtype=peaks.dtype)


def find_dips(
    est: SurfaceEstimate,
    *,
    lengths_m: tuple[float, ...] = DIP_LENGTHS_M,
    threshold: float = DETECTION_THRESHOLD,
    separation_m: float = 1.5,
) -> Dips:
    """Isolated dips in an estimated surface (see the module docstring); :func:`scan_dips` without the trace."""
    return scan_dips(est, lengths_m=lengths_m, threshold=threshold, separation_m=separation_m)[0]


def scan_dips(
    est: SurfaceEstimate,
    *,
    lengths_m: tuple[float, ...] = DIP_LENGTHS_M,
    threshold: float = DETECTION_THRESHOLD,
    separation_m: float = 1.5,
) -> tuple[Dips, DipTrace]:
    """Isolated dips in an estimated surface and the long filters' score trace (module docstring).

    Parameters
    ----------
    est : SurfaceEstimate
        The surface under one wheel (:func:`app.analysis.impacts.surface.surface_estimate`).
    lengths_m : tuple of float
        Lengths of the matched dips, m.
    threshold : float
        Lowest score kept (> 0).
    separation_m : float
        Two dips closer than this are one (the higher score), m.

    Returns
    -------
    dips : Dips
        The candidates of this wheel alone (score >= ``threshold``).
    trace : DipTrace
        The long lengths' (>= 0.2 m, welds) best score every :data:`TRACE_STEP_M`, whatever its value:
        the evidence that is combined across the wheels that meet one track position.
    """
    if not threshold > 0:
        raise ValueError(f"threshold: must be > 0, got {threshold!r}")
    if not lengths_m or any(not (x > 0) for x in lengths_m):
        raise ValueError("lengths_m: must be a non-empty tuple of lengths > 0 m")
    n = est.height.size
    if est.valid.sum() < 1024:
        return Dips.empty(), DipTrace.empty()
    from scipy.signal import find_peaks  # here: see _background_psd

    step = est.step
    short = tuple(x for x in lengths_m if x < _COARSE_FROM_M)
    long = tuple(x for x in lengths_m if x >= _COARSE_FROM_M)
    # the ends of every valid stretch see a truncated filter: no dips within EDGE_M of them
    edge = max(1, int(EDGE_M / step))
    ends = np.flatnonzero(np.diff(np.concatenate([[0], est.valid.astype(np.int8), [0]])))
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    trace = DipTrace.empty()
    # short dips (flats, joints) and long ones (welds) are sought apart: a flat's hit beside a weld
    # is two things, not a side lobe of one
    for bank in (short, long):
        if not bank:
            continue
        if bank is short:
            best, best_l, best_d = _bank(est.height, est.valid, step, est, bank)
        else:  # long dips on a grid _COARSE times coarser (box averages): a quarter of the work
            q = _COARSE
            m = n // q
            hc = est.height[: m * q].reshape(m, q).mean(axis=1)
            vc = est.valid[: m * q].reshape(m, q).all(axis=1)
            bc, lc, dc = _bank(hc, vc, q * step, est, bank)
            # the weld trace: its own bank, background and spread (see WELD_LENGTHS_M, _background_psd)
            each: list[tuple[np.ndarray, np.ndarray]] = []
            _bank(hc, vc, q * step, est, WELD_LENGTHS_M, LONG_SCALE_BLOCK_M, each, tilt=True)
            for sc, _ in each:  # in coarse cells
                sc[_covered((ends - edge) // q, (ends + edge) // q + 1, sc.size)] = -np.inf
            trace = _trace(each, WELD_LENGTHS_M, est.s0, q * step)
            best, best_l, best_d = (np.concatenate([np.repeat(a, q), np.full(n - m * q, fill)])
                                    for a, fill in ((bc, -np.inf), (lc, 0.0), (dc, 0.0)))
        best[_covered(ends - edge, ends + edge, n)] = -np.inf
        peaks, _ = find_peaks(np.where(np.isfinite(best), best, -1e300), height=threshold,
                              distance=max(1, int(separation_m / step)))
        peaks = peaks[best_d[peaks] >= MIN_DEPTH_M]
        peaks = _without_side_lobes(peaks, best, step)
        parts.append((peaks, best[peaks], best_l[peaks], best_d[peaks]))
    if not parts:
        return Dips.empty(), trace
    peaks = np.concatenate([p[0] for p in parts])
    order = np.argsort(peaks, kind="stable")
    peaks = peaks[order]
    score, length, depth = (np.concatenate([p[k] for p in parts])[order] for k in (1, 2, 3))
    if peaks.size == 0:
        return Dips.empty(), trace
    return (Dips(s_m=est.s[peaks], length_m=length, depth_m=depth, score=score,
                 speed_mps=np.nan_to_num(est.speed[peaks], nan=0.0)), trace)


def _trace(each: list[tuple[np.ndarray, np.ndarray]], lengths: tuple[float, ...], s0: float,
           step: float) -> DipTrace:
    """Every :data:`TRACE_STEP_M` and per length the score and depth (NaN where no dip is sought)."""
    per = max(1, int(round(TRACE_STEP_M / step)))
    cell = np.arange(0, each[0][0].size, per) if each else np.zeros(0, dtype=np.int64)
    if cell.size == 0:
        return DipTrace.empty()
    scores, depths = [], []
    for sc, dp in each:
        v = sc[cell]
        ok = np.isfinite(v)
        scores.append(np.where(ok, v, np.nan))
        depths.append(np.where(ok, dp[cell], np.nan))
    return DipTrace(s_m=s0 + (cell + 0.5) * step, lengths_m=np.asarray(lengths, dtype=np.float64),
                    score=np.vstack(scores), depth_m=np.vstack(depths))
