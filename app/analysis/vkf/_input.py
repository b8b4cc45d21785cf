"""Argument checking and lazy slicing of the VKF inputs."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.analysis.orders import OrderTrack

__all__ = ["VKFInput", "prepare_input", "check_mode"]

#: samples per validation / statistics block
STAT_BLOCK = 1 << 16
#: most orders one solve takes (the band of the system grows with the order count)
_MAX_CONST_ORDERS = 256


def _shape(a: Any) -> tuple[int, ...]:
    shape = getattr(a, "shape", None)
    return tuple(shape) if shape is not None else np.shape(a)


def _is_array_like(a: Any) -> bool:
    return hasattr(a, "shape") and hasattr(a, "__getitem__")


@dataclass
class VKFInput:
    """Validated, lazily sliced inputs of one VKF call.

    ``y``, ``freqs`` and ``bandwidth`` may be ndarrays, memory maps, h5py
    datasets or :class:`~app.analysis.orders.OrderTrack` objects; they are
    only read slice by slice.
    """

    y: Any
    y_is_1d: bool
    freqs: Any
    freqs_const: np.ndarray | None
    bandwidth: Any
    bw_const: np.ndarray | None
    fs: float
    q: int
    phase0: np.ndarray
    n: int
    s: int
    channels: int

    def y_slice(self, a: int, b: int) -> np.ndarray:
        """Input samples [a, b) as float64, shape (channels, b - a)."""
        if self.y_is_1d:
            return np.asarray(self.y[a:b], dtype=np.float64)[None, :]
        return np.asarray(self.y[:, a:b], dtype=np.float64)

    def f_slice(self, a: int, b: int) -> np.ndarray:
        """Order frequencies [a, b), Hz, shape (s, b - a)."""
        if self.freqs_const is not None:
            return np.broadcast_to(self.freqs_const[:, None], (self.s, b - a))
        return np.asarray(self.freqs[:, a:b], dtype=np.float64)

    def bw_slice(self, a: int, b: int) -> np.ndarray:
        """Bandwidths [a, b), Hz, shape (s, b - a)."""
        if self.bw_const is not None:
            return np.broadcast_to(self.bw_const[:, None], (self.s, b - a))
        return np.asarray(self.bandwidth[:, a:b], dtype=np.float64)

    def at(self, which: str, a: int, b: int, idx: np.ndarray) -> np.ndarray:
        """``freqs`` or ``bandwidth`` over [a, b) at local indices ``idx``.

        Lazy order tracks are evaluated only at ``idx`` (a decimated grid).
        """
        src, const = (self.freqs, self.freqs_const) if which == "freqs" else (self.bandwidth, self.bw_const)
        if const is not None:
            return np.broadcast_to(const[:, None], (self.s, idx.size))
        if isinstance(src, OrderTrack):
            v = np.asarray(src.speed[a:b], dtype=np.float64)[idx]
            return _track_values(src, v)
        return np.asarray(src[:, a:b], dtype=np.float64)[:, idx]

    def cumsum_freqs(self, a: int, b: int, idx: np.ndarray | None = None) -> np.ndarray:
        """Σ_{a≤l≤k} f_n[l] for k in [a, b) (at local indices ``idx``), Hz·samples."""
        if isinstance(self.freqs, OrderTrack) and self.freqs.floor == 0.0:
            cv = np.cumsum(np.asarray(self.freqs.speed[a:b], dtype=np.float64))
            if idx is not None:
                cv = cv[idx]
            return np.multiply.outer(self.freqs.multipliers, cv)
        cs = np.cumsum(self.f_slice(a, b), axis=1)
        return cs if idx is None else cs[:, idx]

    def sum_freqs(self, a: int, b: int) -> np.ndarray:
        """Σ_{a≤l<b} f_n[l], Hz·samples, shape (s,)."""
        if b <= a:
            return np.zeros(self.s)
        if isinstance(self.freqs, OrderTrack) and self.freqs.floor == 0.0:
            return self.freqs.multipliers * float(np.sum(np.asarray(self.freqs.speed[a:b], dtype=np.float64)))
        return self.f_slice(a, b).sum(axis=1)


def _track_values(track: OrderTrack, v: np.ndarray) -> np.ndarray:
    out = np.multiply.outer(track.multipliers, v)
    if track.floor > 0:
        np.maximum(out, track.floor, out=out)
    return out


def check_mode(decimation: Any, chunk_duration: Any) -> tuple[str | int, float | None]:
    """Validate the ``decimation`` and ``chunk_duration`` keywords."""
    if isinstance(decimation, str):
        if decimation not in ("auto", "off"):
            raise ValueError(f"decimation must be 'auto', 'off' or a positive integer, got {decimation!r}")
    elif isinstance(decimation, bool) or int(decimation) != decimation or int(decimation) < 1:
        raise ValueError(f"decimation must be 'auto', 'off' or a positive integer, got {decimation!r}")
    else:
        decimation = int(decimation)
    if chunk_duration is not None:
        try:
            chunk_duration = float(chunk_duration)
        except (TypeError, ValueError):
            raise ValueError(f"chunk_duration must be a positive number of seconds, got {chunk_duration!r}") from None
        if math.isnan(chunk_duration) or chunk_duration <= 0:
            raise ValueError(f"chunk_duration must be a positive number of seconds, got {chunk_duration!r}")
    return decimation, chunk_duration


def prepare_input(
    y: Any, fs: Any, freqs: Any, bandwidth: Any, filter_order: Any, phase0: Any
) -> VKFInput:
    """Check shapes and scalar arguments; values are checked by :func:`scan_input`.

    Raises
    ------
    ValueError
        With a message naming the offending argument.
    """
    if isinstance(filter_order, bool) or not isinstance(filter_order, (int, np.integer)) or filter_order not in (1, 2, 3):
        raise ValueError(f"filter_order must be 1, 2 or 3, got {filter_order!r}")
    q = int(filter_order)
    try:
        fs = float(fs)
    except (TypeError, ValueError):
        raise ValueError(f"fs must be a positive sample rate in Hz, got {fs!r}") from None
    if not math.isfinite(fs) or fs <= 0:
        raise ValueError(f"fs must be a positive, finite sample rate in Hz, got {fs!r}")

    if not _is_array_like(y):
        y = np.asarray(y)
    yshape = _shape(y)
    dtype = np.dtype(getattr(y, "dtype", np.float64))
    if dtype.kind == "c":
        raise ValueError("y must be real-valued (a measured signal), got a complex array")
    if dtype.kind not in "fiu":
        raise ValueError(f"y must be a numeric array, got dtype {dtype}")
    if len(yshape) not in (1, 2):
        raise ValueError(f"y must be 1-D (N,) or 2-D (channels, N), got shape {yshape}")
    n = yshape[-1]
    channels = 1 if len(yshape) == 1 else yshape[0]
    if n == 0 or channels == 0:
        raise ValueError(f"y is empty (shape {yshape})")
    if n <= 2 * q + 1:
        raise ValueError(f"y needs more than {2 * q + 1} samples for filter_order={q}, got {n}")

    freqs_const = None
    if not _is_array_like(freqs):
        freqs = np.asarray(freqs, dtype=np.float64)
    fshape = _shape(freqs)
    if len(fshape) == 1:
        if fshape[0] == n and n > _MAX_CONST_ORDERS:
            raise ValueError(
                f"freqs has shape ({n},), one value per sample of y: a (s,) array means s constant "
                f"orders; pass one time-varying order as shape (1, N), e.g. freqs[None, :]"
            )
        if fshape[0] > _MAX_CONST_ORDERS:
            raise ValueError(f"freqs has {fshape[0]} orders; at most {_MAX_CONST_ORDERS} are supported")
        freqs_const = np.asarray(freqs, dtype=np.float64)
        s = fshape[0]
    elif len(fshape) == 2:
        if fshape[1] != n:
            raise ValueError(f"freqs must have shape (s, N) with N={n} matching y, got {fshape}")
        s = fshape[0]
    else:
        raise ValueError(f"freqs must have shape (s,) or (s, N), got {fshape}")
    if s == 0:
        raise ValueError("freqs is empty: at least one order is needed")

    bw_const = None
    if not _is_array_like(bandwidth):
        bandwidth = np.asarray(bandwidth, dtype=np.float64)
    bshape = _shape(bandwidth)
    if len(bshape) == 0:
        bw_const = np.full(s, float(np.asarray(bandwidth)))
    elif len(bshape) == 1:
        if bshape[0] != s:
            raise ValueError(f"bandwidth must be a scalar, (s,) or (s, N) with s={s}, got shape {bshape}")
        bw_const = np.asarray(bandwidth, dtype=np.float64)
    elif len(bshape) == 2:
        if bshape != (s, n):
            raise ValueError(f"bandwidth must be a scalar, (s,) or (s, N) = ({s}, {n}), got shape {bshape}")
    else:
        raise ValueError(f"bandwidth must be a scalar, (s,) or (s, N), got shape {bshape}")

    if phase0 is None:
        phase0 = np.zeros(s)
    else:
        phase0 = np.broadcast_to(np.asarray(phase0, dtype=np.float64), (s,)).copy() if np.ndim(phase0) == 0 else np.asarray(phase0, dtype=np.float64)
        if phase0.shape != (s,):
            raise ValueError(f"phase0 must have shape (s,) = ({s},), got {phase0.shape}")
        if not np.all(np.isfinite(phase0)):
            raise ValueError("phase0 contains NaN or inf")

    return VKFInput(
        y=y, y_is_1d=len(yshape) == 1, freqs=freqs, freqs_const=freqs_const,
        bandwidth=bandwidth, bw_const=bw_const, fs=fs, q=q, phase0=phase0,
        n=n, s=s, channels=channels,
    )


@dataclass
class InputStats:
    """Per-block extremes of the order frequencies and bandwidths."""

    block: int
    f_min: np.ndarray
    f_max: np.ndarray
    bw_min: np.ndarray
    bw_max: np.ndarray

    def over(self, a: int, b: int) -> tuple[float, float, float, float]:
        """(f_min, f_max, bw_min, bw_max) over samples [a, b)."""
        i, j = a // self.block, -(-b // self.block)
        return (
            float(self.f_min[i:j].min()), float(self.f_max[i:j].max()),
            float(self.bw_min[i:j].min()), float(self.bw_max[i:j].max()),
        )


def _check_values(name: str, values: np.ndarray, a: int, low: float, high: float, strict_low: bool, unit: str) -> None:
    if not np.all(np.isfinite(values)):
        bad = int(np.argwhere(~np.isfinite(values))[0][-1]) + a
        raise ValueError(f"{name} contains NaN or inf (first at sample {bad})")
    vmin, vmax = float(values.min()), float(values.max())
    if (vmin <= low) if strict_low else (vmin < low):
        what = "must be > " if strict_low else "must be >= "
        raise ValueError(f"{name} {what}{low:g} {unit}, got {vmin:g} {unit}")
    if vmax >= high:
        raise ValueError(f"{name} must be below fs/2 = {high:g} Hz, got {vmax:g} {unit}")


def _extremes(src: Any, const: np.ndarray | None, slicer: Any, a: int, e: int) -> np.ndarray:
    """Values whose min/max/finiteness equal those of the block [a, e).

    For a lazy order track only the speed is scanned: the extremes of
    ``multiplier × speed`` are the products with the speed extremes.
    """
    if const is not None:
        return const[:, None]
    if isinstance(src, OrderTrack):
        v = np.asarray(src.speed[a:e], dtype=np.float64)
        if not np.all(np.isfinite(v)):
            return v[None, :]
        return _track_values(src, np.array([v.min(), v.max()]))
    return slicer(a, e)


def extremes_over(inp: VKFInput, a: int, b: int) -> tuple[float, float, float, float]:
    """(f_min, f_max, bw_min, bw_max) over samples [a, b), exact.

    Order tracks are reduced through their speed extremes, without evaluating
    every order at every sample.
    """
    fb = _extremes(inp.freqs, inp.freqs_const, inp.f_slice, a, b)
    bb = _extremes(inp.bandwidth, inp.bw_const, inp.bw_slice, a, b)
    return float(np.min(fb)), float(np.max(fb)), float(np.min(bb)), float(np.max(bb))


def scan_input(inp: VKFInput) -> InputStats:
    """Check every value of y, freqs and bandwidth; collect per-block extremes.

    Reads the inputs once, block by block, so memory-mapped inputs of any
    length are checked without loading them.
    """
    nyq = inp.fs / 2.0
    nb = -(-inp.n // STAT_BLOCK)
    stats = InputStats(STAT_BLOCK, np.empty(nb), np.empty(nb), np.empty(nb), np.empty(nb))
    for b in range(nb):
        a, e = b * STAT_BLOCK, min((b + 1) * STAT_BLOCK, inp.n)
        yb = inp.y_slice(a, e)
        # A finite sum proves every sample finite (NaN and inf propagate); only a
        # non-finite sum, or an overflow of huge finite values, needs the exact test.
        if not np.isfinite(np.sum(yb)) and not np.all(np.isfinite(yb)):
            ch, k = np.argwhere(~np.isfinite(yb))[0]
            where = f"sample {int(k) + a}" if inp.y_is_1d else f"channel {int(ch)}, sample {int(k) + a}"
            raise ValueError(f"y contains NaN or inf (first at {where})")
        fb = _extremes(inp.freqs, inp.freqs_const, inp.f_slice, a, e)
        _check_values("freqs", fb, a, 0.0, nyq, False, "Hz")
        bb = _extremes(inp.bandwidth, inp.bw_const, inp.bw_slice, a, e)
        _check_values("bandwidth", bb, a, 0.0, nyq, True, "Hz")
        stats.f_min[b], stats.f_max[b] = fb.min(), fb.max()
        stats.bw_min[b], stats.bw_max[b] = bb.min(), bb.max()
    return stats
