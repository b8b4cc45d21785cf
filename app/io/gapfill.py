"""Streaming linear interpolation of NaN gaps in one channel."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["GapFiller"]

WriteBack = Callable[[int, np.ndarray], None]


class GapFiller:
    """Fill NaN runs of a channel that arrives block by block.

    A NaN run between two valid samples is replaced by the straight line
    between them (in sample index); a run before the first valid sample takes
    the first valid value, a run after the last valid sample the last one.
    Runs that extend past the end of a block are completed when the next valid
    sample arrives: the part already handed out is rewritten through
    ``write_back``.

    Parameters
    ----------
    write_back : callable
        ``write_back(start, values)`` overwrites samples ``start:start+len(values)``
        that were emitted earlier (as NaN).
    chunk : int
        Largest slice passed to ``write_back`` at once (memory bound).
    """

    def __init__(self, write_back: WriteBack, chunk: int = 1 << 18) -> None:
        self._write_back = write_back
        self._chunk = int(chunk)
        self.n_nan = 0
        self._last_idx = -1
        self._last_val = np.nan
        self._pending: int | None = None

    def process(self, offset: int, x: np.ndarray) -> np.ndarray:
        """Fill the NaN of block ``x`` (global start ``offset``) as far as possible.

        Returns the block (modified in place); only a trailing NaN run is left
        unfilled until later data (or :meth:`finish`) complete it.
        """
        nan = np.isnan(x)
        if not nan.any():
            if self._pending is not None:
                self._close(offset, x, 0)
            self._last_idx, self._last_val = offset + len(x) - 1, float(x[-1])
            return x
        self.n_nan += int(nan.sum())
        valid = np.flatnonzero(~nan)
        if valid.size == 0:
            if self._pending is None:
                self._pending = offset
            return x
        j0, j1 = int(valid[0]), int(valid[-1])
        if self._pending is not None or j0 > 0:
            if self._pending is None:
                self._pending = offset
            self._close(offset, x, j0)
        inner = np.flatnonzero(nan[j0:j1])
        if inner.size:
            idx = inner + j0
            x[idx] = np.interp(idx, valid, x[valid])
        if j1 < len(x) - 1:
            self._pending = offset + j1 + 1
        self._last_idx, self._last_val = offset + j1, float(x[j1])
        return x

    def _close(self, offset: int, x: np.ndarray, j0: int) -> None:
        """Fill the pending run ``[pending, offset + j0)`` up to the valid sample ``x[j0]``."""
        start, end = self._pending, offset + j0
        assert start is not None
        right_idx, right_val = end, float(x[j0])
        for a in range(start, end, self._chunk):
            b = min(a + self._chunk, end)
            k = np.arange(a, b, dtype=np.float64)
            if self._last_idx < 0:
                vals = np.full(b - a, right_val)
            else:
                w = (k - self._last_idx) / (right_idx - self._last_idx)
                vals = self._last_val + w * (right_val - self._last_val)
            lo, hi = max(a, offset), b
            if lo < hi:
                x[lo - offset : hi - offset] = vals[lo - a :]
            if a < offset:
                self._write_back(a, vals[: min(b, offset) - a])
        self._pending = None

    def finish(self, n: int) -> None:
        """Fill a trailing NaN run with the last valid value (``n`` = total samples).

        Raises
        ------
        ValueError
            If the channel has no valid sample at all.
        """
        if self._pending is None:
            return
        if self._last_idx < 0:
            raise ValueError("channel has no valid sample")
        for a in range(self._pending, n, self._chunk):
            b = min(a + self._chunk, n)
            self._write_back(a, np.full(b - a, self._last_val))
        self._pending = None
