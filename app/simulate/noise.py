"""Band-limited Gaussian noise generated block by block."""

from __future__ import annotations

import numpy as np
from scipy import signal

__all__ = ["BandLimitedNoise"]


class BandLimitedNoise:
    """Gaussian noise band-passed by a Butterworth filter, continuous across blocks.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of white noise.
    fs : float
        Sample rate, Hz.
    std : float
        Standard deviation of the output (stationary), same units as the output.
    band_hz : (float, float)
        Pass band, Hz, ``0 < lo < hi < fs / 2``.
    order : int
        Butterworth order (default 4).
    """

    def __init__(
        self,
        rng: np.random.Generator,
        fs: float,
        std: float,
        band_hz: tuple[float, float],
        order: int = 4,
    ) -> None:
        lo, hi = band_hz
        if not 0 < lo < hi < fs / 2:
            raise ValueError(f"band_hz must satisfy 0 < lo < hi < fs/2, got {band_hz!r} at fs={fs}")
        if not std >= 0:
            raise ValueError(f"std must be >= 0, got {std!r}")
        self._rng = rng
        self.std = float(std)
        self._sos = signal.butter(order, [lo, hi], btype="bandpass", fs=fs, output="sos")
        n_imp = int(min(max(16 * fs / lo, 4096), 2**22))
        impulse = np.zeros(n_imp)
        impulse[0] = 1.0
        h = signal.sosfilt(self._sos, impulse)
        self._scale = self.std / float(np.sqrt(np.sum(h**2)))
        self._zi = np.zeros((self._sos.shape[0], 2))
        if self.std > 0:  # start in the stationary state
            _, self._zi = signal.sosfilt(self._sos, rng.standard_normal(n_imp), zi=self._zi)

    def next(self, n: int) -> np.ndarray:
        """The next ``n`` samples."""
        if self.std == 0.0:
            return np.zeros(n)
        white = self._rng.standard_normal(n)
        y, self._zi = signal.sosfilt(self._sos, white, zi=self._zi)
        return y * self._scale
