"""Instantaneous frequencies of the railway orders tracked by the VKF.

Wheel out-of-roundness order l of a wheel of diameter d_w at speed v turns at
``f_l = l·v / (π d_w)`` (paper Eq. 25); the sleeper passage at spacing d_s
excites ``f_s = v / d_s`` (paper Eq. 26), i.e. ``π d_w / d_s`` = 4.82 wheel
orders for 0.92 m wheels on 0.6 m sleepers.

:class:`OrderTrack` is a lazy ``(s, N)`` array of ``multiplier[n] · speed[k]``
that slices like a NumPy array, so a 30-minute run at 24 kHz with 12 orders
(4 GB as a dense array) can be handed to :func:`app.analysis.vkf.vkf` with
only its speed channel in memory (or memory-mapped).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["wheel_orders", "sleeper_passage", "railway_multipliers", "OrderTrack"]


def _speed_array(speed: Any) -> np.ndarray:
    v = np.asarray(speed, dtype=np.float64)
    if v.ndim > 1:
        raise ValueError(f"speed must be a scalar or 1-D array (m/s), got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("speed contains NaN or inf")
    return v


def wheel_orders(speed: Any, wheel_diameter: float = 0.92, n: int = 11) -> np.ndarray:
    """Frequencies of wheel out-of-roundness orders 1..n.

    Parameters
    ----------
    speed : array_like, shape (N,) or scalar
        Vehicle speed, m/s.
    wheel_diameter : float
        Wheel diameter d_w, m (> 0). Default 0.92.
    n : int
        Number of orders (≥ 1). Default 11.

    Returns
    -------
    ndarray, shape (n, N) (or (n,) for a scalar speed)
        ``f_l = l·v / (π d_w)``, Hz.
    """
    if not np.isfinite(wheel_diameter) or wheel_diameter <= 0:
        raise ValueError(f"wheel_diameter must be a positive length in m, got {wheel_diameter!r}")
    if int(n) != n or n < 1:
        raise ValueError(f"n must be a positive integer, got {n!r}")
    v = _speed_array(speed)
    orders = np.arange(1, int(n) + 1, dtype=np.float64)
    return np.multiply.outer(orders / (np.pi * wheel_diameter), v)


def sleeper_passage(speed: Any, sleeper_spacing: float = 0.6) -> np.ndarray:
    """Sleeper-passage frequency ``f_s = v / d_s``.

    Parameters
    ----------
    speed : array_like, shape (N,) or scalar
        Vehicle speed, m/s.
    sleeper_spacing : float
        Sleeper spacing d_s, m (> 0). Default 0.6.

    Returns
    -------
    ndarray, shape (N,)
        Frequency, Hz.
    """
    if not np.isfinite(sleeper_spacing) or sleeper_spacing <= 0:
        raise ValueError(f"sleeper_spacing must be a positive length in m, got {sleeper_spacing!r}")
    return _speed_array(speed) / sleeper_spacing


def railway_multipliers(
    wheel_diameter: float = 0.92, sleeper_spacing: float = 0.6, n_wheel_orders: int = 11
) -> np.ndarray:
    """Hz per (m/s) of the product's order stack: sleeper passage, then wheel orders 1..n.

    ``np.vstack([sleeper_passage(v, d_s), wheel_orders(v, d_w, n)])`` equals
    ``railway_multipliers(d_w, d_s, n)[:, None] * v``.
    """
    return np.concatenate(
        [sleeper_passage(1.0, sleeper_spacing)[None], wheel_orders(1.0, wheel_diameter, n_wheel_orders)]
    )


class OrderTrack:
    """Lazy ``(s, N)`` array ``multipliers[:, None] * speed[None, :]``.

    Parameters
    ----------
    speed : array_like, shape (N,)
        Speed, m/s: an ndarray, ``np.memmap`` or h5py dataset (sliced lazily).
    multipliers : array_like, shape (s,)
        Factor of each row (Hz per m/s for frequencies; for a bandwidth that is
        constant in orders, ``bandwidth_orders / (π d_w)``).
    floor : float
        Lower bound applied to every value (e.g. a minimum bandwidth in Hz, so
        that a standing train gives a finite filter). Default 0.

    Notes
    -----
    Supports ``shape``, ``ndim``, ``dtype``, ``len`` and slicing with
    ``[:, a:b]`` / ``[i, a:b]``, which is all :func:`~app.analysis.vkf.vkf` needs.
    """

    def __init__(self, speed: Any, multipliers: Any, floor: float = 0.0) -> None:
        self.speed = speed
        self.multipliers = np.asarray(multipliers, dtype=np.float64).reshape(-1)
        self.floor = float(floor)
        if getattr(speed, "ndim", np.ndim(speed)) != 1:
            raise ValueError("speed must be 1-D (m/s)")
        self.shape = (self.multipliers.size, int(len(speed)))
        self.ndim = 2
        self.dtype = np.dtype(np.float64)

    def __len__(self) -> int:
        return self.shape[0]

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        return self[:, :].astype(dtype or np.float64, copy=False)

    def __getitem__(self, key: Any) -> np.ndarray:
        if not isinstance(key, tuple) or len(key) != 2:
            raise IndexError("OrderTrack supports 2-D indexing [rows, samples]")
        rows, cols = key
        v = np.asarray(self.speed[cols], dtype=np.float64)
        out = np.multiply.outer(self.multipliers[rows], v)
        if self.floor > 0:
            np.maximum(out, self.floor, out=out)
        return out
