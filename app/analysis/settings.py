"""Processing settings of a run: the parameters that decide orders, bandwidth and binning.

A :class:`ProcessingSettings` object is stored with every processing job; the
worker, the ``process`` command and the API all read the orders, bandwidth and
binning from it (the railway order recipe, :mod:`app.analysis.recipe`, turns
them into the orders and bandwidths of a wheel), so every stored number can be
traced back to the settings that produced it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

__all__ = ["ProcessingSettings"]


@dataclass(frozen=True)
class ProcessingSettings:
    """Settings of the order-tracking pipeline for one run.

    Parameters
    ----------
    n_wheel_orders : int
        Number of wheel out-of-roundness orders tracked (orders 1..n), 1–30.
        Default 11 (the paper).
    bandwidth_orders : float
        Full -3 dB bandwidth of every order's filter, expressed in wheel
        orders (multiples of the wheel rotation frequency ``v/(pi d_w)``), so
        that the bandwidth in Hz is proportional to speed. Default 0.1: at
        160 km/h (44.4 m/s) and d_w = 0.92 m this is 1.54 Hz; the sleeper
        order lies 0.18 orders from wheel order 5, i.e. 1.8 bandwidths away.
        Range 0.01–1.
    filter_order : int
        Order q of the difference operator of the VKF structural equation,
        1, 2 or 3. Default 2.
    bin_length_m : float
        Length of a profile bin along the track, m. Default 0.25.
    min_speed_kmh : float
        Samples slower than this (km/h) are not used for indicators: the
        orders then sit too close to 0 Hz to be separated. Default 25.
    chunk_seconds : float
        Core length of one processing chunk, s (the engine adds the overlap
        its impulse response needs). Default 60.
    """

    n_wheel_orders: int = 11
    bandwidth_orders: float = 0.1
    filter_order: int = 2
    bin_length_m: float = 0.25
    min_speed_kmh: float = 25.0
    chunk_seconds: float = 60.0

    def __post_init__(self) -> None:
        if not 1 <= int(self.n_wheel_orders) <= 30 or int(self.n_wheel_orders) != self.n_wheel_orders:
            raise ValueError(f"n_wheel_orders must be an integer in 1..30, got {self.n_wheel_orders!r}")
        if not 0.01 <= float(self.bandwidth_orders) <= 1.0:
            raise ValueError(f"bandwidth_orders must be in [0.01, 1], got {self.bandwidth_orders!r}")
        if self.filter_order not in (1, 2, 3):
            raise ValueError(f"filter_order must be 1, 2 or 3, got {self.filter_order!r}")
        if not 0.05 <= float(self.bin_length_m) <= 10.0:
            raise ValueError(f"bin_length_m must be in [0.05, 10] m, got {self.bin_length_m!r}")
        if not 0.0 <= float(self.min_speed_kmh) <= 200.0:
            raise ValueError(f"min_speed_kmh must be in [0, 200] km/h, got {self.min_speed_kmh!r}")
        if not 1.0 <= float(self.chunk_seconds) <= 3600.0:
            raise ValueError(f"chunk_seconds must be in [1, 3600] s, got {self.chunk_seconds!r}")

    def to_dict(self) -> dict[str, Any]:
        """Return the settings as a JSON-serialisable dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None) -> ProcessingSettings:
        """Build settings from a dict; missing keys take their defaults.

        Raises
        ------
        ValueError
            If a key is unknown or a value is out of range.
        """
        data = dict(data or {})
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown processing setting(s): {', '.join(sorted(unknown))}")
        return cls(**data)
