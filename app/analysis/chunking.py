"""Layout of overlapping chunks joined by a raised-cosine crossfade.

A long signal is cut into chunks whose *cores* tile ``[0, n)``. Each chunk is
solved over its core plus an overlap on both sides (the impulse-response
length of its filter, supplied by the caller) and contributes to the output
with a weight that is 1 in its core and ramps over a short crossfade at each
seam; the weights of neighbouring chunks sum to exactly 1.

The same layout serves the VKF engine (:func:`app.analysis.vkf.vkf`) and the
worker's chunk tasks, so both join chunks identically.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = ["Chunk", "plan_chunk_layout", "ramp"]


def ramp(index: np.ndarray, boundary: int, length: int) -> np.ndarray:
    """Raised-cosine step from 0 to 1 over [boundary - length/2, boundary + length/2)."""
    x = (index - (boundary - length / 2.0) + 0.5) / length
    return np.sin(0.5 * np.pi * np.clip(x, 0.0, 1.0)) ** 2


@dataclass(frozen=True)
class Chunk:
    """One chunk of a signal (sample indices).

    Attributes
    ----------
    index : int
        Position in the signal, from 0.
    start, stop : int
        Core range; the cores tile ``[0, n)``.
    lo, hi : int
        Solve range, core plus overlap.
    out_lo, out_hi : int
        Samples with a non-zero crossfade weight.
    fade_in, fade_out : (int, int) or None
        (boundary sample, crossfade length) at the start / end seam.
    """

    index: int
    start: int
    stop: int
    lo: int
    hi: int
    out_lo: int
    out_hi: int
    fade_in: tuple[int, int] | None
    fade_out: tuple[int, int] | None

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form (for task queues)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Chunk:
        """Inverse of :meth:`to_dict`."""
        d = dict(d)
        for key in ("fade_in", "fade_out"):
            if d.get(key) is not None:
                d[key] = tuple(int(x) for x in d[key])
        return cls(**d)

    def weight(self, index: np.ndarray) -> np.ndarray:
        """Crossfade weight at global sample indices (0 outside [out_lo, out_hi))."""
        w = np.ones(index.shape)
        if self.fade_in is not None:
            w *= ramp(index, *self.fade_in)
        if self.fade_out is not None:
            w *= 1.0 - ramp(index, *self.fade_out)
        w[(index < self.out_lo) | (index >= self.out_hi)] = 0.0
        return w


def plan_chunk_layout(n: int, core: int, overlap: Callable[[int, int], int]) -> list[Chunk]:
    """Cut ``[0, n)`` into chunks of ``core`` samples with overlap and crossfade.

    Parameters
    ----------
    n : int
        Number of samples (> 0).
    core : int
        Core length, samples (> 0); a last core shorter than ``core/2`` is
        merged into the previous one. ``core >= n`` gives one chunk.
    overlap : callable
        ``overlap(a, b)`` → samples of overlap a chunk covering [a, b) needs
        on each side (may be called with a < 0 or b > n). Each chunk is sized
        from its core, then once more from the core widened by that guess,
        so that slower stretches next to a seam are accounted for.

    Returns
    -------
    list of Chunk
    """
    if n <= 0 or core <= 0:
        raise ValueError(f"n and core must be positive, got n={n}, core={core}")
    if core >= n:
        return [Chunk(0, 0, n, 0, n, 0, n, None, None)]
    bounds = list(range(0, n, core)) + [n]
    if len(bounds) > 2 and bounds[-1] - bounds[-2] < core // 2:
        del bounds[-2]
    k = len(bounds) - 1
    pads = []
    for i in range(k):
        a, b = bounds[i], bounds[i + 1]
        guess = overlap(a, b)
        pads.append(max(guess, overlap(max(a - guess - core // 4, 0), min(b + guess + core // 4, n))))
    # crossfade of each interior seam: short against the cores, never longer
    # than the overlap that protects it
    fades = [0] * (k + 1)
    for i in range(1, k):
        fade = min(pads[i - 1], pads[i], (bounds[i] - bounds[i - 1]) // 4, (bounds[i + 1] - bounds[i]) // 4)
        fades[i] = max(2 * (fade // 2), 2)
    chunks = []
    for i in range(k):
        a, b = bounds[i], bounds[i + 1]
        out_lo = a - fades[i] // 2 if i > 0 else 0
        out_hi = b + fades[i + 1] // 2 if i < k - 1 else n
        chunks.append(
            Chunk(
                index=i, start=a, stop=b,
                lo=max(out_lo - pads[i], 0), hi=min(out_hi + pads[i], n),
                out_lo=out_lo, out_hi=out_hi,
                fade_in=(a, fades[i]) if i > 0 else None,
                fade_out=(b, fades[i + 1]) if i < k - 1 else None,
            )
        )
    return chunks
